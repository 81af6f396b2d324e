// DDS Security: the folder deploy/dds/make_security.sh makes, the checks that name a wrong file
// before Fast DDS refuses it, and what the governance and permissions do on the wire (one
// process, UDP profile).
#include "indrive/dds/security.h"

#include <gtest/gtest.h>
#include <openssl/evp.h>
#include <openssl/pem.h>
#include <openssl/x509.h>

#include <atomic>
#include <cstdio>
#include <fstream>
#include <map>
#include <memory>
#include <pugixml.hpp>
#include <set>
#include <thread>

#include "child_process.h"
#include "synthetic_traffic.h"
#include "testing.h"

namespace indrive::dds {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;

// Every participant here loads the same profiles file (one file per process, see dds.cc).
std::string profiles() { return testing::source_path("deploy/dds/default.xml").string(); }

using testing::run_command;

std::string make_security(const fs::path& dir, const std::string& options = "") {
  std::string output;
  const int code =
      run_command("bash '" + testing::source_path("deploy/dds/make_security.sh").string() + "' '" +
                      dir.string() + "' " + options,
                  output);
  EXPECT_EQ(code, 0) << output;
  return output;
}

// A folder made in `dir`, once per test process (making one takes about a second).
fs::path made_in(const testing::TempDir& dir) {
  make_security(dir.path() / "run");
  return dir.path() / "run";
}

// The run's folder, and a second run's whose files must be refused next to the first one's.
const fs::path& security_dir() {
  static const testing::TempDir dir("indrive-security");
  static const fs::path path = made_in(dir);
  return path;
}

const fs::path& other_security_dir() {
  static const testing::TempDir dir("indrive-security-other");
  static const fs::path path = made_in(dir);
  return path;
}

// A copy of the run's folder that a test may damage.
struct DamagedCopy {
  testing::TempDir temp{"indrive-security-copy"};
  fs::path dir = temp.path() / "run";
  DamagedCopy() { fs::copy(security_dir(), dir, fs::copy_options::recursive); }
  void replace(const std::string& name, const fs::path& from) {
    fs::copy_file(from, dir / name, fs::copy_options::overwrite_existing);
  }
};

std::string check_error(const fs::path& dir, const std::string& role) {
  return testing::error_of<DdsError>([&] { check_security_files(dir, role); });
}

template <typename F>
std::string error_of(F&& make) {
  return testing::error_of<DdsError>(std::forward<F>(make));
}

// Re-issues <role>.pem in `dir` with the same subject and key, signed by the folder's CA, valid
// from now + start_s to now + end_s (negative: in the past).
void reissue_certificate(const fs::path& dir, const std::string& role, long start_s, long end_s) {
  const auto read_pem = [](const fs::path& path, auto reader) {
    FILE* file = std::fopen(path.c_str(), "r");
    EXPECT_NE(file, nullptr) << path;
    auto* object = reader(file, nullptr, nullptr, nullptr);
    std::fclose(file);
    EXPECT_NE(object, nullptr) << path;
    return object;
  };
  X509* ca = read_pem(dir / "ca.pem", PEM_read_X509);
  EVP_PKEY* ca_key = read_pem(dir / "ca.key", PEM_read_PrivateKey);
  X509* old = read_pem(dir / (role + ".pem"), PEM_read_X509);
  X509* certificate = X509_new();
  X509_set_version(certificate, 2);
  ASN1_INTEGER_set(X509_get_serialNumber(certificate), 4242);
  X509_set_issuer_name(certificate, X509_get_subject_name(ca));
  X509_set_subject_name(certificate, X509_get_subject_name(old));
  X509_set_pubkey(certificate, X509_get0_pubkey(old));
  X509_gmtime_adj(X509_getm_notBefore(certificate), start_s);
  X509_gmtime_adj(X509_getm_notAfter(certificate), end_s);
  ASSERT_GT(X509_sign(certificate, ca_key, EVP_sha256()), 0);
  FILE* out = std::fopen((dir / (role + ".pem")).c_str(), "w");
  ASSERT_NE(out, nullptr);
  PEM_write_X509(out, certificate);
  std::fclose(out);
  X509_free(certificate);
  X509_free(old);
  EVP_PKEY_free(ca_key);
  X509_free(ca);
}

// The topics a role's permissions document lets it publish and subscribe.
std::map<std::string, std::set<std::string>> grants_of(const std::string& role) {
  pugi::xml_document document;
  const auto path = security_dir() / ("permissions-" + role + ".xml");
  EXPECT_TRUE(document.load_file(path.c_str())) << path;
  std::map<std::string, std::set<std::string>> grants;
  const auto grant = document.child("dds").child("permissions").child("grant");
  EXPECT_STREQ(grant.child_value("default"), "DENY") << role;
  for (const auto& rule : grant.children("allow_rule")) {
    for (const char* kind : {"publish", "subscribe"}) {
      for (const auto& topic : rule.child(kind).child("topics").children("topic")) {
        grants[kind].insert(topic.child_value());
      }
    }
  }
  EXPECT_FALSE(grant.child("deny_rule")) << role;
  return grants;
}

TEST(DdsSecurityFiles, EveryRoleOfTheScriptsFolderValidates) {
  for (const auto role : kSecurityRoles) {
    const SecurityFiles files = check_security_files(security_dir(), std::string(role));
    EXPECT_EQ(files.certificate.filename(), std::string(role) + ".pem");
    EXPECT_TRUE(files.permissions.is_absolute()) << files.permissions;
  }
  // The private keys are for their owner only.
  const auto mode = fs::status(security_dir() / "learner.key").permissions();
  EXPECT_EQ(mode & (fs::perms::group_all | fs::perms::others_all), fs::perms::none);
}

TEST(DdsSecurityFiles, PermissionsGrantWhatEachRoleNeeds) {
  using Topics = std::set<std::string>;
  const auto learner = grants_of("learner");
  EXPECT_EQ(learner.at("publish"), (Topics{"indrive/policy", "indrive/policy_announce",
                                           "indrive/allowance", "indrive/heartbeat"}));
  EXPECT_EQ(learner.at("subscribe"), (Topics{"indrive/trajectory", "indrive/episode_result",
                                             "indrive/snapshot_request", "indrive/heartbeat"}));
  const auto actor = grants_of("actor");
  EXPECT_EQ(actor.at("publish"), (Topics{"indrive/trajectory", "indrive/episode_result",
                                         "indrive/heartbeat", "indrive/snapshot_request"}));
  EXPECT_EQ(actor.at("subscribe"), (Topics{"indrive/policy", "indrive/policy_announce",
                                           "indrive/allowance", "indrive/heartbeat"}));
  const auto evaluator = grants_of("evaluator");
  EXPECT_EQ(evaluator.at("publish"),
            (Topics{"indrive/episode_result", "indrive/snapshot_request", "indrive/heartbeat"}));
  EXPECT_EQ(evaluator.at("subscribe"),
            (Topics{"indrive/policy", "indrive/policy_announce", "indrive/heartbeat"}));
  const auto observer = grants_of("observer");
  EXPECT_EQ(observer.count("publish"), 0u);
  EXPECT_EQ(observer.at("subscribe"), (Topics{"indrive/*"}));
}

TEST(DdsSecurityFiles, GovernanceAdmitsOnlyAuthenticatedEncryptedParticipants) {
  pugi::xml_document document;
  ASSERT_TRUE(document.load_file((security_dir() / "governance.xml").c_str()));
  const auto rule = document.child("dds").child("domain_access_rules").child("domain_rule");
  EXPECT_STREQ(rule.child_value("allow_unauthenticated_participants"), "false");
  EXPECT_STREQ(rule.child_value("enable_join_access_control"), "true");
  for (const char* kind : {"discovery_protection_kind", "liveliness_protection_kind"}) {
    EXPECT_STREQ(rule.child_value(kind), "ENCRYPT") << kind;
  }
  // Submessages and payloads are encrypted per topic below; the outer RTPS encryption is off
  // because Fast DDS 2.9 aborts when it grows a full message (make_security.sh says more).
  EXPECT_STREQ(rule.child_value("rtps_protection_kind"), "NONE");
  const auto topic = rule.child("topic_access_rules").child("topic_rule");
  EXPECT_STREQ(topic.child_value("topic_expression"), "indrive/*");
  EXPECT_STREQ(topic.child_value("enable_read_access_control"), "true");
  EXPECT_STREQ(topic.child_value("enable_write_access_control"), "true");
  EXPECT_STREQ(topic.child_value("metadata_protection_kind"), "ENCRYPT");
  EXPECT_STREQ(topic.child_value("data_protection_kind"), "ENCRYPT");
}

TEST(DdsSecurityFiles, ScriptRefusesToOverwriteAFolderWithoutForce) {
  testing::TempDir temp("indrive-security-force");
  const auto dir = temp.path() / "run";
  make_security(dir, "--days 2 --domain 9");
  std::string output;
  const std::string script = testing::source_path("deploy/dds/make_security.sh").string();
  EXPECT_NE(run_command("bash '" + script + "' '" + dir.string() + "'", output), 0);
  EXPECT_NE(output.find("--force"), std::string::npos) << output;
  const std::string old_ca = testing::slurp(dir / "ca.pem");
  EXPECT_NE(old_ca, "");
  const std::string printed = make_security(dir, "--force");
  EXPECT_NE(printed.find("--dds-security"), std::string::npos) << "usage hint: " << printed;
  EXPECT_NE(testing::slurp(dir / "ca.pem"), old_ca) << "--force makes a new CA";
  EXPECT_NE(testing::slurp(dir / "governance.xml").find("<id_range>"), std::string::npos);
  EXPECT_EQ(check_error(dir, "actor"), "(no exception)");
}

TEST(DdsSecurityFiles, UnknownRoleListsTheRoles) {
  const auto message = check_error(security_dir(), "pilot");
  EXPECT_NE(message.find("'pilot'"), std::string::npos) << message;
  EXPECT_NE(message.find("learner, actor, evaluator, observer"), std::string::npos) << message;
  EXPECT_NE(check_error(security_dir(), "").find("no DDS Security role"), std::string::npos);
}

TEST(DdsSecurityFiles, MissingFolderAndFilesAreNamed) {
  const auto folder = check_error("/nonexistent/security", "learner");
  EXPECT_NE(folder.find("/nonexistent/security"), std::string::npos) << folder;
  EXPECT_NE(folder.find("make_security.sh"), std::string::npos) << folder;

  for (const std::string name :
       {"ca.pem", "governance.p7s", "learner.pem", "learner.key", "permissions-learner.p7s"}) {
    DamagedCopy copy;
    fs::remove(copy.dir / name);
    const auto message = check_error(copy.dir, "learner");
    EXPECT_NE(message.find((copy.dir / name).string()), std::string::npos) << message;
    EXPECT_NE(message.find("is missing"), std::string::npos) << message;
  }
  // Another role's files do not stand in for this role's.
  DamagedCopy copy;
  fs::remove(copy.dir / "permissions-actor.p7s");
  EXPECT_EQ(check_error(copy.dir, "learner"), "(no exception)");
  EXPECT_NE(check_error(copy.dir, "actor").find("permissions-actor.p7s"), std::string::npos);
}

TEST(DdsSecurityFiles, ExpiredAndNotYetValidCertificatesSayWhen) {
  DamagedCopy copy;
  reissue_certificate(copy.dir, "learner", -10 * 86400, -5 * 86400);
  const auto expired = check_error(copy.dir, "learner");
  EXPECT_NE(expired.find("learner.pem"), std::string::npos) << expired;
  EXPECT_NE(expired.find("has expired"), std::string::npos) << expired;
  EXPECT_NE(expired.find("UTC"), std::string::npos) << "the date: " << expired;

  reissue_certificate(copy.dir, "learner", 5 * 86400, 10 * 86400);
  const auto early = check_error(copy.dir, "learner");
  EXPECT_NE(early.find("learner.pem"), std::string::npos) << early;
  EXPECT_NE(early.find("not valid yet"), std::string::npos) << early;

  // The same subject and key, valid now, signed by the same CA: accepted again.
  reissue_certificate(copy.dir, "learner", -60, 86400);
  EXPECT_EQ(check_error(copy.dir, "learner"), "(no exception)");
}

TEST(DdsSecurityFiles, CertificateOfAnotherCaIsNamed) {
  DamagedCopy copy;
  copy.replace("learner.pem", other_security_dir() / "learner.pem");
  copy.replace("learner.key", other_security_dir() / "learner.key");
  const auto message = check_error(copy.dir, "learner");
  EXPECT_NE(message.find((copy.dir / "learner.pem").string()), std::string::npos) << message;
  EXPECT_NE(message.find("is not signed by"), std::string::npos) << message;
}

TEST(DdsSecurityFiles, KeyOfAnotherRoleIsNamed) {
  DamagedCopy copy;
  copy.replace("learner.key", security_dir() / "actor.key");
  const auto message = check_error(copy.dir, "learner");
  EXPECT_NE(message.find((copy.dir / "learner.key").string()), std::string::npos) << message;
  EXPECT_NE(message.find("does not belong"), std::string::npos) << message;
}

TEST(DdsSecurityFiles, DocumentsSignedByAnotherCaAreNamed) {
  for (const std::string name : {"permissions-learner.p7s", "governance.p7s"}) {
    DamagedCopy copy;
    copy.replace(name, other_security_dir() / name);
    const auto message = check_error(copy.dir, "learner");
    EXPECT_NE(message.find((copy.dir / name).string()), std::string::npos) << message;
    EXPECT_NE(message.find("is not signed by"), std::string::npos) << message;
  }
}

TEST(DdsSecurityFiles, PermissionsOfAnotherRoleAreNamed) {
  DamagedCopy copy;
  copy.replace("permissions-learner.p7s", security_dir() / "permissions-actor.p7s");
  const auto message = check_error(copy.dir, "learner");
  EXPECT_NE(message.find("permissions-learner.p7s"), std::string::npos) << message;
  EXPECT_NE(message.find("CN=actor"), std::string::npos) << message;
  EXPECT_NE(message.find("CN=learner"), std::string::npos) << message;
}

TEST(DdsSecurityFiles, DiscoveryServerClientsAreRefused) {
  // Fast DDS 2.9 aborts a secure client of a server without security: refuse before that.
  eprosima::fastdds::dds::DomainParticipantQos qos;
  qos.wire_protocol().builtin.discovery_config.discoveryProtocol =
      eprosima::fastrtps::rtps::DiscoveryProtocol_t::CLIENT;
  const auto message = error_of([&] { apply_security(qos, security_dir(), "actor"); });
  EXPECT_NE(message.find("Discovery Server"), std::string::npos) << message;
  EXPECT_TRUE(qos.properties().properties().empty() || !security_enabled(qos));

  eprosima::fastdds::dds::DomainParticipantQos simple;
  apply_security(simple, security_dir(), "actor");
  EXPECT_TRUE(security_enabled(simple));
  const auto* permissions = eprosima::fastrtps::rtps::PropertyPolicyHelper::find_property(
      simple.properties(), "dds.sec.access.builtin.Access-Permissions.permissions");
  ASSERT_NE(permissions, nullptr);
  EXPECT_EQ(*permissions, "file://" + (security_dir() / "permissions-actor.p7s").string());
}

TEST(DdsSecurityFiles, ParticipantChecksTheFilesFirst) {
  const auto message = error_of([] {
    Participant participant({.domain_id = testing::unique_domain_id(),
                             .profiles_file = profiles(),
                             .security_dir = "/nonexistent/security",
                             .security_role = "learner"});
  });
  EXPECT_NE(message.find("make_security.sh"), std::string::npos) << message;
}

// A participant of the run's folder in `role` (empty: no security at all).
std::unique_ptr<Participant> participant_as(const std::string& role) {
  ParticipantOptions options{.domain_id = testing::unique_domain_id(), .profiles_file = profiles()};
  if (!role.empty()) {
    options.security_dir = security_dir().string();
    options.security_role = role;
  }
  return std::make_unique<Participant>(options);
}

TEST(DdsSecurityWire, PolicyReachesASecureReaderButNoParticipantWithoutSecurity) {
  const std::string run_id = "secure-" + std::to_string(::getpid());
  auto learner = participant_as("learner");
  auto evaluator = participant_as("evaluator");
  auto outsider = participant_as("");

  // Written before any reader exists: TRANSIENT_LOCAL keeps it for the secure late joiner.
  auto writer = learner->make_writer<msg::PolicySnapshot>();
  ASSERT_TRUE(writer->write(testing::make_synthetic_snapshot(run_id, 3, 64 << 10)));

  std::atomic<int> secure_ok{0}, secure_other{0}, outsider_samples{0};
  auto secure_reader =
      evaluator->make_reader<msg::PolicySnapshot>([&](const msg::PolicySnapshot& snapshot) {
        const bool ours = validate(snapshot, run_id) == DropReason::kOk &&
                          snapshot.version() == 3 &&
                          testing::compare_with_synthetic(snapshot).empty();
        (ours ? secure_ok : secure_other).fetch_add(1);
      });
  // The outsider's reader counts the learner's snapshots only: its own injector below is in the
  // same participant and reaches it.
  auto outsider_reader =
      outsider->make_reader<msg::PolicySnapshot>([&](const msg::PolicySnapshot& snapshot) {
        if (snapshot.version() == 3) outsider_samples.fetch_add(1);
      });
  // The outsider also tries to inject a snapshot of its own.
  auto injector = outsider->make_writer<msg::PolicySnapshot>();
  ASSERT_TRUE(injector->write(testing::make_synthetic_snapshot(run_id, 99, 1 << 10)));

  for (int i = 0; i < 3000 && secure_ok.load() == 0; ++i) std::this_thread::sleep_for(10ms);
  EXPECT_EQ(secure_ok.load(), 1) << "the secure evaluator never got the learner's snapshot";
  // A few more seconds for anything that could still leak to or from the outsider.
  std::this_thread::sleep_for(3s);
  EXPECT_EQ(outsider_samples.load(), 0) << "a participant without security read the policy";
  EXPECT_EQ(outsider_reader->matched(), 1) << "the outsider's own injector only";
  EXPECT_EQ(injector->matched(), 1) << "the outsider's own reader only";
  EXPECT_EQ(secure_other.load(), 0) << "the secure reader took a sample from the outsider";
  EXPECT_EQ(writer->matched(), 1) << "only the secure reader matches the learner's writer";
  // What each participant's ledger says (peers.h): the two secure ones authenticated each
  // other; the outsider is present to them without security, never refused or pending.
  for (const Participant* secure : {learner.get(), evaluator.get()}) {
    const PeerLedger::Counts peers = secure->peers();
    EXPECT_EQ(peers.authenticated, 1) << secure->guid_prefix();
    EXPECT_EQ(peers.pending, 0) << secure->guid_prefix();
    EXPECT_EQ(peers.refused, 0) << secure->guid_prefix();
    EXPECT_EQ(peers.unsecured, 1) << secure->guid_prefix();
  }
  EXPECT_EQ(outsider->peers().authenticated, 0);
  EXPECT_EQ(outsider->peers().pending, 0);
}

TEST(DdsSecurityWire, PermissionsRefuseEndpointsOutsideTheRole) {
  auto actor = participant_as("actor");
  const auto policy = error_of([&] { actor->make_writer<msg::PolicySnapshot>(); });
  EXPECT_NE(policy.find("writer on 'indrive/policy'"), std::string::npos) << policy;
  EXPECT_NE(policy.find("permissions"), std::string::npos) << policy;
  EXPECT_NE(policy.find("permissions-actor.p7s"), std::string::npos) << policy;
  // What the role may do still works.
  EXPECT_NO_THROW(actor->make_writer<msg::TrajectoryChunk>());
  EXPECT_NO_THROW(actor->make_reader<msg::PolicySnapshot>([](const msg::PolicySnapshot&) {}));
  const auto chunks = error_of(
      [&] { actor->make_reader<msg::TrajectoryChunk>([](const msg::TrajectoryChunk&) {}); });
  EXPECT_NE(chunks.find("reader on 'indrive/trajectory'"), std::string::npos) << chunks;
  EXPECT_NE(chunks.find("permissions"), std::string::npos) << chunks;

  // The observer reads everything and writes nothing.
  auto observer = participant_as("observer");
  EXPECT_NO_THROW(observer->make_reader<msg::TrajectoryChunk>([](const msg::TrajectoryChunk&) {}));
  EXPECT_NO_THROW(observer->make_reader<msg::StepAllowance>([](const msg::StepAllowance&) {}));
  const auto heartbeat = error_of([&] { observer->make_writer<msg::Heartbeat>(); });
  EXPECT_NE(heartbeat.find("permissions-observer.p7s"), std::string::npos) << heartbeat;

  // Without security the same writer is fine and the message does not blame permissions.
  auto plain = participant_as("");
  EXPECT_NO_THROW(plain->make_writer<msg::PolicySnapshot>());
}

}  // namespace
}  // namespace indrive::dds
