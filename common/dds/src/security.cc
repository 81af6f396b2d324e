#include "indrive/dds/security.h"

#include <openssl/err.h>
#include <openssl/evp.h>
#include <openssl/pem.h>
#include <openssl/pkcs7.h>
#include <openssl/x509.h>
#include <openssl/x509_vfy.h>
#include <unistd.h>

#include <algorithm>
#include <cstdlib>
#include <ctime>
#include <iomanip>
#include <memory>
#include <pugixml.hpp>
#include <sstream>
#include <vector>

#include "indrive/basics/config.h"
#include "indrive/basics/log.h"

namespace indrive::dds {
namespace {

namespace fs = std::filesystem;

template <auto Free>
struct FreeWith {
  template <typename T>
  void operator()(T* pointer) const {
    Free(pointer);
  }
};
using Bio = std::unique_ptr<BIO, FreeWith<BIO_free_all>>;
using Certificate = std::unique_ptr<X509, FreeWith<X509_free>>;
using PrivateKey = std::unique_ptr<EVP_PKEY, FreeWith<EVP_PKEY_free>>;
using Store = std::unique_ptr<X509_STORE, FreeWith<X509_STORE_free>>;
using StoreContext = std::unique_ptr<X509_STORE_CTX, FreeWith<X509_STORE_CTX_free>>;
using Pkcs7 = std::unique_ptr<PKCS7, FreeWith<PKCS7_free>>;

constexpr const char* kRemake =
    "re-run deploy/dds/make_security.sh for the run and copy the role's files from that folder";

[[noreturn]] void fail(const fs::path& file, const std::string& problem, const std::string& todo) {
  throw DdsError("DDS Security file '" + file.string() + "' " + problem + "; " + todo);
}

// OpenSSL's queued error reasons as " (reason; reason)", or "" when it queued none. Clears the
// queue, so the next check starts from an empty one.
std::string openssl_reason() {
  std::string reasons;
  const char* data = nullptr;
  int flags = 0;
  while (const unsigned long code = ERR_get_error_all(nullptr, nullptr, nullptr, &data, &flags)) {
    char text[256];
    ERR_error_string_n(code, text, sizeof(text));
    if (!reasons.empty()) reasons += "; ";
    reasons += text;
    // Some reasons carry detail, e.g. "Verify error:unable to get local issuer certificate".
    if ((flags & ERR_TXT_STRING) != 0 && data != nullptr && *data != '\0') {
      reasons += std::string(": ") + data;
    }
  }
  return reasons.empty() ? "" : " (" + reasons + ")";
}

std::string bio_text(BIO* bio) {
  char* data = nullptr;
  const long size = BIO_get_mem_data(bio, &data);
  return size > 0 ? std::string(data, static_cast<std::size_t>(size)) : std::string();
}

Bio open_file(const fs::path& file) {
  ERR_clear_error();
  Bio bio(BIO_new_file(file.c_str(), "r"));
  if (!bio) fail(file, "could not be opened" + openssl_reason(), kRemake);
  return bio;
}

Certificate read_certificate(const fs::path& file) {
  auto bio = open_file(file);
  Certificate certificate(PEM_read_bio_X509(bio.get(), nullptr, nullptr, nullptr));
  if (!certificate) fail(file, "is not a PEM certificate" + openssl_reason(), kRemake);
  return certificate;
}

// "2026-12-01 07:35:27 UTC" for an ASN1 time, the form people compare with `date -u`.
std::string time_text(const ASN1_TIME* time) {
  std::tm parts{};
  if (time == nullptr || ASN1_TIME_to_tm(time, &parts) != 1) return "(unreadable date)";
  std::ostringstream text;
  text << std::put_time(&parts, "%Y-%m-%d %H:%M:%S UTC");
  return text.str();
}

void check_validity(const X509* certificate, const fs::path& file) {
  const ASN1_TIME* not_before = X509_get0_notBefore(certificate);
  const ASN1_TIME* not_after = X509_get0_notAfter(certificate);
  // X509_cmp_current_time: -1 when the time is before now, 1 after now, 0 when unreadable.
  const int start = X509_cmp_current_time(not_before);
  const int end = X509_cmp_current_time(not_after);
  if (start == 0 || end == 0) fail(file, "has an unreadable validity period", kRemake);
  if (start > 0) {
    fail(file, "is not valid yet: its validity starts " + time_text(not_before),
         "check this host's clock (date -u), or wait until then");
  }
  if (end < 0) {
    fail(file, "has expired: its validity ended " + time_text(not_after),
         "make a new folder with deploy/dds/make_security.sh (--days sets how long it lasts) "
         "and copy the role's files from it");
  }
}

// The certificate's subject as the access-control plugin writes it (RFC 2253, most specific
// part first), which is how a grant's subject_name must read.
std::string subject_of(X509* certificate) {
  Bio bio(BIO_new(BIO_s_mem()));
  X509_NAME_print_ex(bio.get(), X509_get_subject_name(certificate), 0,
                     XN_FLAG_RFC2253 & ~ASN1_STRFLGS_ESC_MSB);
  return bio_text(bio.get());
}

// The comma-separated parts of a distinguished name, trimmed, so "CN=a, O=b" equals "CN=a,O=b".
std::vector<std::string> name_parts(const std::string& name) {
  std::vector<std::string> parts;
  std::stringstream stream(name);
  std::string part;
  while (std::getline(stream, part, ',')) {
    const auto first = part.find_first_not_of(" \t\n");
    const auto last = part.find_last_not_of(" \t\n");
    parts.push_back(first == std::string::npos ? "" : part.substr(first, last - first + 1));
  }
  return parts;
}

// A permissions date ("2026-12-01T07:35:27") the way Fast DDS reads it: as local time.
std::time_t grant_time(const std::string& text, bool& ok) {
  std::tm parts{};
  std::istringstream stream(text);
  stream >> std::get_time(&parts, "%Y-%m-%dT%H:%M:%S");
  ok = !stream.fail();
  parts.tm_isdst = -1;
  return ok ? std::mktime(&parts) : 0;
}

// Reads an S/MIME document and checks that the CA in `store` signed it; returns its content.
std::string read_signed(const fs::path& file, X509_STORE* store, const fs::path& ca_file) {
  auto bio = open_file(file);
  BIO* content = nullptr;
  Pkcs7 document(SMIME_read_PKCS7(bio.get(), &content));
  Bio content_owner(content);
  if (!document) fail(file, "is not an S/MIME signed document" + openssl_reason(), kRemake);
  Bio out(BIO_new(BIO_s_mem()));
  // The same verification the access-control plugin does: the signer must chain to ca.pem.
  if (PKCS7_verify(document.get(), nullptr, store, content, out.get(), PKCS7_TEXT) != 1) {
    fail(file, "is not signed by '" + ca_file.string() + "'" + openssl_reason(),
         "it belongs to another run's CA: copy it from the folder that holds this ca.pem, or "
         "re-run deploy/dds/make_security.sh and copy the role's files from that folder");
  }
  return bio_text(out.get());
}

void check_permissions(const std::string& text, const fs::path& file, X509* certificate,
                       const fs::path& certificate_file) {
  pugi::xml_document document;
  if (const auto parsed = document.load_string(text.c_str()); !parsed) {
    fail(
        file,
        std::string("does not hold a readable permissions document (") + parsed.description() + ")",
        kRemake);
  }
  const std::string subject = subject_of(certificate);
  const auto wanted = name_parts(subject);
  std::string granted;
  for (const auto& grant : document.child("dds").child("permissions").children("grant")) {
    const std::string grant_subject = grant.child_value("subject_name");
    if (name_parts(grant_subject) != wanted) {
      granted += (granted.empty() ? "'" : ", '") + grant_subject + "'";
      continue;
    }
    // Fast DDS ignores a grant outside its validity; say so instead of failing later.
    const auto validity = grant.child("validity");
    const std::string from = validity.child_value("not_before");
    const std::string until = validity.child_value("not_after");
    bool from_ok = false, until_ok = false;
    const std::time_t start = grant_time(from, from_ok);
    const std::time_t end = grant_time(until, until_ok);
    if (!from_ok || !until_ok) {
      fail(file, "has no readable validity (not_before '" + from + "', not_after '" + until + "')",
           kRemake);
    }
    const std::time_t now = std::time(nullptr);
    if (now < start) {
      fail(file, "grants '" + subject + "' only from " + from + " (read as this host's local time)",
           "check this host's clock and time zone, or wait until then");
    }
    if (now > end) {
      fail(file, "grants '" + subject + "' only until " + until + " (this host's local time)",
           "make a new folder with deploy/dds/make_security.sh and copy the role's files from it");
    }
    return;
  }
  fail(file,
       "grants " + (granted.empty() ? std::string("no subject") : granted) + " but '" +
           certificate_file.string() + "' is '" + subject + "'",
       "the permissions belong to another role or run: copy the permissions file made together "
       "with that certificate, or " +
           std::string(kRemake));
}

// An OpenSSL password callback that supplies none: an encrypted key fails instead of prompting
// on the terminal (Fast DDS would not prompt either).
int no_password(char*, int, int, void*) { return 0; }

std::string file_uri(const fs::path& path) { return "file://" + path.string(); }

void set_property(eprosima::fastrtps::rtps::PropertySeq& properties, const std::string& name,
                  const std::string& value) {
  for (auto& property : properties) {
    if (property.name() == name) {
      property.value() = value;
      return;
    }
  }
  properties.emplace_back(name, value);
}

}  // namespace

SecurityFiles check_security_files(const std::filesystem::path& dir, const std::string& role) {
  if (std::find(kSecurityRoles.begin(), kSecurityRoles.end(), role) == kSecurityRoles.end()) {
    std::string roles;
    for (const auto known : kSecurityRoles) {
      roles += (roles.empty() ? "" : ", ") + std::string(known);
    }
    throw DdsError((role.empty() ? std::string("no DDS Security role")
                                 : "unknown DDS Security role '" + role + "'") +
                   ": set dds.security_role to one of " + roles +
                   " (each has its own certificate and permissions)");
  }
  std::error_code error;
  if (!fs::is_directory(dir, error)) {
    throw DdsError("DDS Security folder '" + dir.string() +
                   "' does not exist or is not a folder; make it with "
                   "deploy/dds/make_security.sh " +
                   dir.string() + " or copy the role's files from the CA host");
  }
  const fs::path base = fs::absolute(dir, error).lexically_normal();
  const SecurityFiles files{.identity_ca = base / "ca.pem",
                            .governance = base / "governance.p7s",
                            .certificate = base / (role + ".pem"),
                            .private_key = base / (role + ".key"),
                            .permissions = base / ("permissions-" + role + ".p7s")};
  const std::string needed = "the " + role + " role needs ca.pem, governance.p7s, " + role +
                             ".pem, " + role + ".key and permissions-" + role + ".p7s";
  for (const auto* file : {&files.identity_ca, &files.governance, &files.certificate,
                           &files.private_key, &files.permissions}) {
    if (!fs::is_regular_file(*file, error)) {
      fail(*file, "is missing (" + needed + ")",
           "copy it from the run's security folder on the CA host, or " + std::string(kRemake));
    }
    if (::access(file->c_str(), R_OK) != 0) {
      fail(*file, "is not readable by this user",
           "check its owner and mode (the processes of the run must be able to read it)");
    }
  }

  const auto ca = read_certificate(files.identity_ca);
  check_validity(ca.get(), files.identity_ca);
  const auto certificate = read_certificate(files.certificate);
  check_validity(certificate.get(), files.certificate);

  Store store(X509_STORE_new());
  ERR_clear_error();
  if (!store || X509_STORE_add_cert(store.get(), ca.get()) != 1) {
    fail(files.identity_ca, "could not be used as a trust anchor" + openssl_reason(), kRemake);
  }
  StoreContext context(X509_STORE_CTX_new());
  if (!context ||
      X509_STORE_CTX_init(context.get(), store.get(), certificate.get(), nullptr) != 1) {
    throw DdsError("OpenSSL could not set up a certificate check" + openssl_reason());
  }
  // The flags the authentication plugin verifies identities with.
  X509_STORE_CTX_set_flags(context.get(),
                           X509_V_FLAG_CHECK_SS_SIGNATURE | X509_V_FLAG_POLICY_CHECK);
  if (X509_verify_cert(context.get()) != 1) {
    const int code = X509_STORE_CTX_get_error(context.get());
    ERR_clear_error();
    fail(files.certificate,
         "is not signed by '" + files.identity_ca.string() + "' (" +
             X509_verify_cert_error_string(code) + ")",
         "it belongs to another run's CA: copy " + role + ".pem, " + role +
             ".key and permissions-" + role + ".p7s from the folder that holds this ca.pem, or " +
             kRemake);
  }

  {
    auto bio = open_file(files.private_key);
    PrivateKey key(PEM_read_bio_PrivateKey(bio.get(), nullptr, no_password, nullptr));
    if (!key) {
      fail(files.private_key, "is not an unencrypted PEM private key" + openssl_reason(), kRemake);
    }
    if (X509_check_private_key(certificate.get(), key.get()) != 1) {
      ERR_clear_error();
      fail(files.private_key,
           "does not belong to '" + files.certificate.string() +
               "' (it is another role's or another run's key)",
           "copy the " + role + ".key made together with " + role + ".pem, or " + kRemake);
    }
  }

  read_signed(files.governance, store.get(), files.identity_ca);
  const std::string permissions = read_signed(files.permissions, store.get(), files.identity_ca);
  check_permissions(permissions, files.permissions, certificate.get(), files.certificate);
  return files;
}

void apply_security(eprosima::fastdds::dds::DomainParticipantQos& qos,
                    const std::filesystem::path& dir, const std::string& role) {
  // A secure participant that discovers through a server without security makes Fast DDS 2.9
  // abort the process (an assertion in its security manager, with no log line first); refuse
  // the combination with a message instead. ROS_DISCOVERY_SERVER turns a participant into such
  // a client inside Fast DDS, so it counts too.
  using eprosima::fastrtps::rtps::DiscoveryProtocol_t;
  const auto discovery = qos.wire_protocol().builtin.discovery_config.discoveryProtocol;
  const char* server_variable = std::getenv("ROS_DISCOVERY_SERVER");
  if (discovery != DiscoveryProtocol_t::SIMPLE ||
      (server_variable != nullptr && *server_variable != '\0')) {
    throw DdsError(
        "DDS Security does not work with a Discovery Server here (the profile's discovery "
        "protocol is not SIMPLE, or ROS_DISCOVERY_SERVER is set): Fast DDS 2.9 aborts a secure "
        "participant whose server runs without security. Use deploy/dds/default.xml or "
        "single_host.xml with --dds-security, or drop --dds-security on that network");
  }
  const SecurityFiles files = check_security_files(dir, role);
  auto& properties = qos.properties().properties();
  set_property(properties, "dds.sec.auth.plugin", "builtin.PKI-DH");
  set_property(properties, "dds.sec.auth.builtin.PKI-DH.identity_ca", file_uri(files.identity_ca));
  set_property(properties, "dds.sec.auth.builtin.PKI-DH.identity_certificate",
               file_uri(files.certificate));
  set_property(properties, "dds.sec.auth.builtin.PKI-DH.private_key", file_uri(files.private_key));
  set_property(properties, "dds.sec.access.plugin", "builtin.Access-Permissions");
  // One CA signs identities and documents alike, so it is the permissions CA too.
  set_property(properties, "dds.sec.access.builtin.Access-Permissions.permissions_ca",
               file_uri(files.identity_ca));
  set_property(properties, "dds.sec.access.builtin.Access-Permissions.governance",
               file_uri(files.governance));
  set_property(properties, "dds.sec.access.builtin.Access-Permissions.permissions",
               file_uri(files.permissions));
  set_property(properties, "dds.sec.crypto.plugin", "builtin.AES-GCM-GMAC");
  // Fast DDS's key-exchange warnings are dropped in the log sink (dds.cc, kHarmlessLines).
  INDRIVE_LOG(kInfo, "dds") << "DDS Security on: role " << role << ", files from "
                            << files.identity_ca.parent_path().string();
}

bool security_enabled(const eprosima::fastdds::dds::DomainParticipantQos& qos) {
  for (const auto& property : qos.properties().properties()) {
    if (property.name() == "dds.sec.access.plugin" && !property.value().empty()) return true;
  }
  return false;
}

std::string permissions_note(const eprosima::fastdds::dds::DomainParticipantQos& qos,
                             const std::string& action) {
  if (!security_enabled(qos)) return "";
  std::string permissions = "the role's permissions file";
  for (const auto& property : qos.properties().properties()) {
    if (property.name() == "dds.sec.access.builtin.Access-Permissions.permissions") {
      permissions = fs::path(property.value()).filename().string();
    }
  }
  std::ostringstream note;
  note << "; with DDS Security on, the permissions may deny it: " << permissions
       << " may not allow this role to " << action
       << " it (deploy/dds/make_security.sh lists what each role may do)";
  return note.str();
}

std::string security_role(const config::Config& config, const std::string& own_role) {
  const std::string configured = config.get<std::string>("dds.security_role");
  return configured.empty() ? own_role : configured;
}

}  // namespace indrive::dds
