// DDS Security (authentication, access control, encryption) for a Participant, as an opt-in.
//
// deploy/dds/make_security.sh makes a run's folder: a CA, one certificate, key and signed
// permissions document per role, and a signed governance document. A process that names the
// folder (ParticipantOptions::security_dir, config key dds.security_dir, flag --dds-security)
// joins only participants of the same CA, encrypts everything it sends, and may publish and
// subscribe only what its role's permissions grant.
//
//   indrive::dds::Participant participant({.domain_id = 7, .profiles_file = profiles,
//                                          .security_dir = "runs/r1/security",
//                                          .security_role = "actor"});
//
// The Participant constructor calls apply_security; check_security_files can also be called on
// its own (e.g. by a --check-config). Fast DDS rejects bad files with a log line and a null
// participant; these checks run first and say which file is wrong and what to do.
#pragma once

#include <array>
#include <fastdds/dds/domain/qos/DomainParticipantQos.hpp>
#include <filesystem>
#include <string>
#include <string_view>
#include <utility>

#include "indrive/dds/participant.h"

namespace indrive::config {
class Config;
}  // namespace indrive::config

namespace indrive::dds {

// The roles make_security.sh issues certificates and permissions for. "observer" may subscribe
// every topic and publish none (monitors, dashboards, tests).
inline constexpr std::array<std::string_view, 4> kSecurityRoles = {"learner", "actor", "evaluator",
                                                                   "observer"};

// The command-line flag that names the security folder, as an alias of dds.security_dir for
// config::parse_command_line (like kProfilesFlag).
inline const std::pair<std::string, std::string> kSecurityFlag{"--dds-security",
                                                               "dds.security_dir"};

// Absolute paths of the files one role uses from a security folder.
struct SecurityFiles {
  std::filesystem::path identity_ca;  // ca.pem
  std::filesystem::path governance;   // governance.p7s
  std::filesystem::path certificate;  // <role>.pem
  std::filesystem::path private_key;  // <role>.key
  std::filesystem::path permissions;  // permissions-<role>.p7s
};

// Checks the files of `role` in the folder `dir` with OpenSSL: each exists and is readable, the
// certificates parse, the role's certificate is within its validity and signed by ca.pem, the
// key belongs to it, governance.p7s and permissions-<role>.p7s are signed by ca.pem, and the
// permissions grant the certificate's subject. Throws DdsError naming the file, what is wrong
// and what to do; returns the paths on success.
SecurityFiles check_security_files(const std::filesystem::path& dir, const std::string& role);

// Checks the files (check_security_files) and sets the builtin PKI-DH, Access-Permissions and
// AES-GCM-GMAC plugins with them in the participant's properties, replacing same-named ones
// from the XML profile.
void apply_security(eprosima::fastdds::dds::DomainParticipantQos& qos,
                    const std::filesystem::path& dir, const std::string& role);

// True when `qos` has the access-control plugin set, i.e. permissions may refuse endpoints.
bool security_enabled(const eprosima::fastdds::dds::DomainParticipantQos& qos);

// For an error about an endpoint Fast DDS refused: "; with DDS Security on, ... may not allow
// this role to <action> it" when security is on, else "". `action` is "publish" or "subscribe to".
std::string permissions_note(const eprosima::fastdds::dds::DomainParticipantQos& qos,
                             const std::string& action);

// The role a program runs as: dds.security_role of `config` when set, else `own_role`.
std::string security_role(const config::Config& config, const std::string& own_role);

}  // namespace indrive::dds
