#include "indrive/dds/participant.h"

#include <arpa/inet.h>
#include <fastdds/rtps/common/Locator.h>
#include <fastdds/rtps/participant/ParticipantDiscoveryInfo.h>
#include <fastdds/rtps/transport/shared_mem/SharedMemTransportDescriptor.h>
#include <fastrtps/utils/IPLocator.h>
#include <netdb.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <condition_variable>
#include <cstdlib>
#include <fastdds/dds/domain/DomainParticipantFactory.hpp>
#include <fastdds/dds/domain/DomainParticipantListener.hpp>
#include <fastdds/dds/log/Log.hpp>
#include <iomanip>
#include <iterator>
#include <sstream>
#include <string_view>
#include <thread>

#include "indrive/basics/check.h"
#include "indrive/basics/config.h"
#include "indrive/dds/security.h"

namespace indrive::dds {
namespace {

using eprosima::fastdds::dds::DomainParticipantFactory;
using eprosima::fastrtps::types::ReturnCode_t;

// Fast DDS log lines that say nothing about the run, with why; each is dropped, and the first
// one of a kind is replaced by its note (when it has one).
struct HarmlessLine {
  const char* category;  // Fast DDS's category; nullptr: any
  const char* text;      // found in the message
  const char* note;      // logged once instead, at info level; nullptr: nothing
};
constexpr HarmlessLine kHarmlessLines[] = {
    // A snapshot writer with several matched readers sends its fragments once per receiving
    // port with no reader named, so every reader of that participant looks at them. The policy
    // reader takes them; a best-effort reader of another topic (the heartbeat reader) finds no
    // such writer among its own and warns, once per fragment: about 4,000 lines in two minutes
    // of a two-host run, for data that did arrive. Reliable readers stay silent in the same
    // case, and shared memory (single_host.xml) sends a snapshot unfragmented.
    {"RTPS_MSG_IN", "received DATA_FRAG from unknown writer",
     "[RTPS_MSG_IN] fragments of a sample meant for another reader of this participant reach "
     "the heartbeat reader too; Fast DDS's 'received DATA_FRAG from unknown writer' warning for "
     "them is not shown (harmless)"},
    // With DDS Security, while two participants exchange keys, messages that overtake the key
    // material are dropped (and sent again by the reliable protocol); Fast DDS warns once per
    // message, about a hundred lines per peer at start-up.
    {nullptr, "No key material yet", nullptr},
};

// Forwards Fast DDS log entries to the project's sink, so nothing lands on stdout.
class SinkConsumer : public eprosima::fastdds::dds::LogConsumer {
 public:
  void Consume(const eprosima::fastdds::dds::Log::Entry& entry) override {
    using Kind = eprosima::fastdds::dds::Log::Kind;
    const char* category = entry.context.category != nullptr ? entry.context.category : "";
    for (std::size_t i = 0; i < std::size(kHarmlessLines); ++i) {
      const HarmlessLine& line = kHarmlessLines[i];
      if ((line.category != nullptr && std::string_view(category) != line.category) ||
          entry.message.find(line.text) == std::string::npos) {
        continue;
      }
      if (dropped_[i].fetch_add(1) == 0 && line.note != nullptr) {
        log::write(log::Level::kInfo, "fastdds", line.note, __FILE__, __LINE__);
      }
      return;
    }
    const log::Level level = entry.kind == Kind::Error     ? log::Level::kError
                             : entry.kind == Kind::Warning ? log::Level::kWarn
                                                           : log::Level::kDebug;
    const std::string message = std::string("[") + category + "] " + entry.message;
    log::write(level, "fastdds", message,
               entry.context.filename != nullptr ? entry.context.filename : "fastdds",
               entry.context.line);
  }

 private:
  std::atomic<std::uint64_t> dropped_[std::size(kHarmlessLines)] = {};
};

std::filesystem::path canonical_or_same(const std::filesystem::path& path) {
  std::error_code error;
  auto result = std::filesystem::weakly_canonical(path, error);
  return error ? path : result;
}

// Fast DDS keeps every loaded profile per process and, when a second file defines a profile
// name again, logs an error but keeps the first definition and reports success. Every
// shipped file uses the same names, so a second file would silently not take effect: refuse
// it, including a FASTRTPS_DEFAULT_PROFILES_FILE that Fast DDS loads on its own.
// Called before loading (commit = false) and after a successful load (commit = true), so a
// file that fails to load does not block a good one later.
void claim_profiles_file(const std::filesystem::path& path, bool commit) {
  static std::mutex mutex;
  static std::filesystem::path claimed;
  const auto wanted = canonical_or_same(path);
  const char* from_env = std::getenv(kProfilesEnvVar);
  if (from_env != nullptr && *from_env != '\0' && canonical_or_same(from_env) != wanted) {
    throw DdsError(std::string("FASTRTPS_DEFAULT_PROFILES_FILE names '") + from_env +
                   "' but the dds-profiles argument names '" + path.string() +
                   "'; Fast DDS would load both and keep the first one's profiles. Unset the "
                   "variable or pass the same file");
  }
  std::lock_guard<std::mutex> lock(mutex);
  if (claimed.empty()) {
    if (commit) claimed = wanted;
  } else if (claimed != wanted) {
    throw DdsError("this process already uses DDS profiles from '" + claimed.string() +
                   "'; it cannot switch to '" + path.string() +
                   "' (Fast DDS keeps the first definition of each profile name)");
  }
}

// Points every discovery server of a client profile at `address`. The profile keeps the
// servers' GUID prefixes (which `fastdds discovery -i N` fixes); only their locators change.
void apply_discovery_server(eprosima::fastdds::dds::DomainParticipantQos& qos,
                            const ServerAddress& address,
                            const std::filesystem::path& profiles_file) {
  const std::string& source = address.source;
  using eprosima::fastrtps::rtps::DiscoveryProtocol_t;
  auto& discovery = qos.wire_protocol().builtin.discovery_config;
  if (discovery.discoveryProtocol != DiscoveryProtocol_t::CLIENT &&
      discovery.discoveryProtocol != DiscoveryProtocol_t::SUPER_CLIENT) {
    throw DdsError(source + " names a discovery server, but the DDS profiles file '" +
                   profiles_file.string() +
                   "' does not make discovery-server clients (it discovers peers by "
                   "multicast); use deploy/dds/discovery_server.xml, or unset " +
                   source);
  }
  if (discovery.m_DiscoveryServers.empty()) {
    throw DdsError("the DDS profiles file '" + profiles_file.string() +
                   "' lists no <RemoteServer> whose address " + source + " could replace");
  }
  eprosima::fastrtps::rtps::Locator_t locator;
  locator.kind = LOCATOR_KIND_UDPv4;
  eprosima::fastrtps::rtps::IPLocator::setIPv4(locator, address.ipv4);
  locator.port = static_cast<std::uint32_t>(address.port);
  for (auto& server : discovery.m_DiscoveryServers) {
    server.metatrafficUnicastLocatorList.clear();
    server.metatrafficUnicastLocatorList.push_back(locator);
  }
}

}  // namespace

int shared_memory_participant_id(long pid, int created_before) {
  INDRIVE_CHECK(pid >= 0 && created_before >= 0) << "pid " << pid << ", count " << created_before;
  // The pid is mixed first (splitmix64's finaliser): processes started one after another have
  // consecutive pids, and with pid + count the second participant of one process (a rejoin)
  // took the first one of the next (seen on 2026-12-06: actor 0's replacement took id 41, actor
  // 1's, and the fault test's watch did not hear it for 10 s).
  auto mixed = static_cast<std::uint64_t>(pid);
  mixed = (mixed ^ (mixed >> 30)) * 0xbf58476d1ce4e5b9ULL;
  mixed = (mixed ^ (mixed >> 27)) * 0x94d049bb133111ebULL;
  mixed ^= mixed >> 31;
  return static_cast<int>(
      (mixed % kSharedMemoryParticipantIds + static_cast<std::uint64_t>(created_before)) %
      kSharedMemoryParticipantIds);
}

ServerAddress parse_discovery_server(const std::string& text, const std::string& source) {
  ServerAddress address;
  address.host = text;
  address.source = source;
  const auto colon = text.rfind(':');
  if (colon != std::string::npos) {
    address.host = text.substr(0, colon);
    const std::string port = text.substr(colon + 1);
    const bool digits = !port.empty() && port.size() <= 5 &&
                        port.find_first_not_of("0123456789") == std::string::npos;
    address.port = digits ? std::stoi(port) : 0;
    if (address.port < 1 || address.port > 65535) {
      throw DdsError(source + " is '" + text +
                     "': the port after ':' must be 1..65535 (HOST:PORT, e.g. 10.0.0.1:" +
                     std::to_string(kDefaultDiscoveryPort) + ")");
    }
  }
  if (address.host.empty()) {
    throw DdsError(source + " is '" + text +
                   "': give the server as HOST:PORT or HOST, e.g. 10.0.0.1:" +
                   std::to_string(kDefaultDiscoveryPort));
  }
  addrinfo hints{};
  hints.ai_family = AF_INET;  // the shipped profiles carry data over UDPv4
  hints.ai_socktype = SOCK_DGRAM;
  addrinfo* found = nullptr;
  const int status = ::getaddrinfo(address.host.c_str(), nullptr, &hints, &found);
  if (status != 0 || found == nullptr) {
    throw DdsError(source + " is '" + text + "': cannot resolve '" + address.host +
                   "' to an IPv4 address (" + ::gai_strerror(status) +
                   "); check the name, or give the server's address");
  }
  char buffer[INET_ADDRSTRLEN] = {};
  ::inet_ntop(AF_INET, &reinterpret_cast<const sockaddr_in*>(found->ai_addr)->sin_addr, buffer,
              sizeof buffer);
  ::freeaddrinfo(found);
  address.ipv4 = buffer;
  return address;
}

std::string ServerAddress::describe() const {
  return host + ":" + std::to_string(port) + (host != ipv4 ? " (" + ipv4 + ")" : "") + " from " +
         source;
}

std::optional<ServerAddress> resolve_discovery_server(const std::string& configured) {
  if (!configured.empty()) {
    return parse_discovery_server(configured, "--discovery-server (dds.discovery_server)");
  }
  const char* from_env = std::getenv(kDiscoveryServerEnvVar);
  if (from_env == nullptr || *from_env == '\0') return std::nullopt;
  return parse_discovery_server(from_env, std::string("$") + kDiscoveryServerEnvVar);
}

void route_fastdds_log() {
  static std::once_flag once;
  std::call_once(once, [] {
    using eprosima::fastdds::dds::Log;
    Log::ClearConsumers();
    Log::RegisterConsumer(std::make_unique<SinkConsumer>());
    Log::SetVerbosity(Log::Kind::Warning);
  });
}

void declare_config(config::Schema& schema) {
  schema.add_int("dds.domain_id", 0, "DDS domain of the run; processes of one run share it", 0, 232)
      .add_string("dds.profiles_file", "",
                  "XML profiles file (deploy/dds/*.xml); empty: FASTRTPS_DEFAULT_PROFILES_FILE")
      .add_string("dds.participant_profile", "indrive_participant",
                  "<participant> profile in the XML profiles file")
      .add_string("dds.discovery_server", "",
                  "HOST:PORT of the discovery server (discovery_server.xml profile); empty: "
                  "$INDRIVE_DISCOVERY_SERVER, then the profile's address")
      .add_string("dds.security_dir", "",
                  "folder made by deploy/dds/make_security.sh; empty: no DDS Security")
      .add_choice("dds.security_role", "", {"", "learner", "actor", "evaluator", "observer"},
                  "DDS Security role (certificate and permissions); empty: the program's own")
      .add_float("dds.snapshot_rate_mb_s", 0.0,
                 "throughput limit of the learner's snapshot writer in MB/s, below the slowest "
                 "link snapshots cross (0: the profile's, 100 MB/s in the shipped ones)",
                 0.0);
}

ParticipantOptions participant_options(const config::Config& config) {
  return {.domain_id = config.get<int>("dds.domain_id"),
          .profiles_file = config.get<std::string>("dds.profiles_file"),
          .participant_profile = config.get<std::string>("dds.participant_profile"),
          .discovery_server = config.get<std::string>("dds.discovery_server"),
          .security_dir = config.get<std::string>("dds.security_dir"),
          .security_role = config.get<std::string>("dds.security_role"),
          .snapshot_rate_mb_s = config.get<double>("dds.snapshot_rate_mb_s")};
}

std::filesystem::path resolve_profiles_file(const std::string& explicit_path) {
  std::string path = explicit_path;
  std::string source = "the dds-profiles argument";
  if (path.empty()) {
    const char* from_env = std::getenv(kProfilesEnvVar);
    if (from_env == nullptr || *from_env == '\0') {
      throw DdsError(
          "no DDS profiles file: pass --dds-profiles <file> or set "
          "FASTRTPS_DEFAULT_PROFILES_FILE (deploy/dds/default.xml for several hosts, "
          "deploy/dds/single_host.xml for one host)");
    }
    path = from_env;
    source = kProfilesEnvVar;
  }
  std::error_code error;
  if (!std::filesystem::is_regular_file(path, error)) {
    throw DdsError("DDS profiles file '" + path + "' (from " + source +
                   ") does not exist or is not a file; use one of deploy/dds/*.xml");
  }
  return path;
}

namespace {

std::string prefix_of(const eprosima::fastrtps::rtps::GUID_t& guid) {
  std::ostringstream out;
  out << guid.guidPrefix;
  return out.str();
}

// Feeds a participant's PeerLedger from Fast DDS's callbacks (on its threads) and logs what
// matters to someone deploying with DDS Security: each authentication and each refusal.
class PeerListener final : public eprosima::fastdds::dds::DomainParticipantListener {
 public:
  PeerListener(PeerLedger& peers, bool secure) : peers_(peers), secure_(secure) {}

  void on_participant_discovery(
      eprosima::fastdds::dds::DomainParticipant*,
      eprosima::fastrtps::rtps::ParticipantDiscoveryInfo&& info) override {
    using Info = eprosima::fastrtps::rtps::ParticipantDiscoveryInfo;
    const std::string guid = prefix_of(info.info.m_guid);
    switch (info.status) {
      case Info::DISCOVERED_PARTICIPANT: {
        // Called before the handshake starts; a participant without an identity token has no
        // DDS Security and is never authenticated (a secure participant ignores it).
        const bool offers_identity = !info.info.identity_token_.class_id().empty();
        peers_.discovered(guid, secure_ && offers_identity, PeerLedger::Clock::now());
        if (secure_ && !offers_identity) {
          INDRIVE_LOG(kInfo, "dds")
              << "participant " << guid << " has no DDS Security and is ignored";
        }
        break;
      }
      case Info::REMOVED_PARTICIPANT:
      case Info::DROPPED_PARTICIPANT:
        peers_.left(guid);
        break;
      default:
        break;
    }
  }

  void onParticipantAuthentication(
      eprosima::fastdds::dds::DomainParticipant*,
      eprosima::fastrtps::rtps::ParticipantAuthenticationInfo&& info) override {
    using Info = eprosima::fastrtps::rtps::ParticipantAuthenticationInfo;
    const std::string guid = prefix_of(info.guid);
    if (info.status == Info::AUTHORIZED_PARTICIPANT) {
      const double waited = peers_.authenticated(guid, PeerLedger::Clock::now());
      INDRIVE_LOG(kInfo, "dds") << "DDS Security authenticated participant " << guid << " "
                                << std::fixed << std::setprecision(2) << waited
                                << " s after discovering it";
    } else if (peers_.refused(guid)) {
      INDRIVE_LOG(kWarn, "dds")
          << "DDS Security refused participant " << guid
          << ": its identity certificate is not signed by this run's identity CA, or it failed "
             "the handshake (a participant of another run's security folder?)";
    }
  }

 private:
  PeerLedger& peers_;
  bool secure_;
};

}  // namespace

Participant::Participant(const ParticipantOptions& options)
    : profiles_file_(resolve_profiles_file(options.profiles_file)),
      snapshot_rate_mb_s_(options.snapshot_rate_mb_s),
      domain_id_(options.domain_id) {
  if (!(snapshot_rate_mb_s_ >= 0.0)) {
    throw DdsError(
        "dds.snapshot_rate_mb_s must be 0 (the profile's limit) or a rate in MB/s, got " +
        std::to_string(snapshot_rate_mb_s_));
  }
  route_fastdds_log();
  if (domain_id_ < 0 || domain_id_ > 232) {
    throw DdsError("DDS domain id " + std::to_string(domain_id_) +
                   " is out of range; use 0..232 (UDP port numbers are derived from it)");
  }
  claim_profiles_file(profiles_file_, /*commit=*/false);
  auto* factory = DomainParticipantFactory::get_instance();
  // Loading the same file twice is harmless: Fast DDS remembers the files it has parsed.
  if (factory->load_XML_profiles_file(profiles_file_.string()) != ReturnCode_t::RETCODE_OK) {
    throw DdsError("DDS profiles file '" + profiles_file_.string() +
                   "' could not be loaded (malformed XML, an unknown element, or a profile name "
                   "already loaded from another file); the log above has Fast DDS's reason");
  }
  claim_profiles_file(profiles_file_, /*commit=*/true);
  eprosima::fastdds::dds::DomainParticipantQos qos;
  if (factory->get_participant_qos_from_profile(options.participant_profile, qos) !=
      ReturnCode_t::RETCODE_OK) {
    throw DdsError("DDS profiles file '" + profiles_file_.string() +
                   "' has no <participant> profile named '" + options.participant_profile + "'");
  }
  if (const auto server = resolve_discovery_server(options.discovery_server)) {
    apply_discovery_server(qos, *server, profiles_file_);
    INDRIVE_LOG(kInfo, "dds") << "discovery server " << server->describe();
  }
  // After the discovery server: security refuses discovery-server clients (see apply_security).
  if (!options.security_dir.empty()) {
    apply_security(qos, options.security_dir, options.security_role);
  }
  const auto& transports = qos.transport().user_transports;
  const auto shared_memory_transports =
      std::count_if(transports.begin(), transports.end(), [](const auto& transport) {
        return dynamic_cast<const eprosima::fastdds::rtps::SharedMemTransportDescriptor*>(
                   transport.get()) != nullptr;
      });
  uses_shared_memory_ = qos.transport().use_builtin_transports || shared_memory_transports > 0;
  const bool shared_memory_only = !qos.transport().use_builtin_transports &&
                                  shared_memory_transports > 0 &&
                                  shared_memory_transports == std::ssize(transports);
  // Only where no UDP port depends on it (firewall rules name the UDP ports of the lowest ids).
  if (shared_memory_only && qos.wire_protocol().participant_id < 0) {
    static std::atomic<int> created{0};
    qos.wire_protocol().participant_id =
        shared_memory_participant_id(static_cast<long>(::getpid()), created.fetch_add(1));
  }
  participant_id_ = qos.wire_protocol().participant_id;
  const bool secure = security_enabled(qos);
  listener_ = std::make_unique<PeerListener>(peers_, secure);
  // No status of the mask: the readers' and writers' own listeners get theirs.
  const auto mask = eprosima::fastdds::dds::StatusMask::none();
  participant_ = factory->create_participant(domain_id_, qos, listener_.get(), mask);
  if (participant_ == nullptr && shared_memory_only && participant_id_ >= 0) {
    INDRIVE_LOG(kWarn, "dds") << "no participant with id " << participant_id_ << " in domain "
                              << domain_id_ << "; letting Fast DDS choose the id";
    qos.wire_protocol().participant_id = participant_id_ = -1;
    participant_ = factory->create_participant(domain_id_, qos, listener_.get(), mask);
  }
  if (participant_ == nullptr) {
    throw DdsError("could not create a DDS participant in domain " + std::to_string(domain_id_) +
                   " with profile '" + options.participant_profile + "' of '" +
                   profiles_file_.string() + "' (transport setup failed" +
                   (security_enabled(qos) ? ", or DDS Security refused the governance or the "
                                            "permissions for this domain"
                                          : "") +
                   "; see the log)");
  }
  publisher_ = participant_->create_publisher(eprosima::fastdds::dds::PUBLISHER_QOS_DEFAULT);
  subscriber_ = participant_->create_subscriber(eprosima::fastdds::dds::SUBSCRIBER_QOS_DEFAULT);
  if (publisher_ == nullptr || subscriber_ == nullptr) {
    participant_->delete_contained_entities();
    factory->delete_participant(participant_);
    throw DdsError("could not create the DDS publisher/subscriber of the participant");
  }
  INDRIVE_LOG(kInfo, "dds") << "participant " << guid_prefix() << " in domain " << domain_id_
                            << (participant_id_ >= 0
                                    ? " (id " + std::to_string(participant_id_) + ")"
                                    : std::string())
                            << " from " << profiles_file_.string()
                            << (secure ? " with DDS Security" : "");
  if (secure) {
    stall_watch_ = std::jthread([this](std::stop_token stop) {
      std::mutex mutex;
      std::condition_variable_any wake;
      std::unique_lock lock(mutex);
      const auto after = std::chrono::duration_cast<PeerLedger::Clock::duration>(
          std::chrono::duration<double>(kHandshakeStallS));
      while (true) {
        wake.wait_for(lock, stop, std::chrono::seconds(1), [] { return false; });
        if (stop.stop_requested()) return;
        for (const auto& stalled : peers_.newly_stalled(PeerLedger::Clock::now(), after)) {
          INDRIVE_LOG(kWarn, "dds")
              << "DDS Security has not authenticated participant " << stalled.guid << " "
              << std::fixed << std::setprecision(0) << stalled.pending_s
              << " s after discovering it (handshakes take 0.02-2.1 s in the tests): nothing "
                 "flows between the two until it completes, and a stalled one never does. "
                 "Harmless between two actors or evaluators (each uses only what the learner "
                 "writes and ignores the others' heartbeats); between the learner and an actor or "
                 "evaluator, that one replaces its participant once it has not heard the learner "
                 "for actor.rejoin_after_s";
        }
      }
    });
  }
}

std::string Participant::guid_prefix() const { return prefix_of(participant_->guid()); }

Participant::~Participant() {
  stall_watch_ = std::jthread();  // stops and joins it
  // Writers and readers are owned by the caller and must already be gone (they hold pointers
  // into this participant); topics, publisher and subscriber go with the participant.
  INDRIVE_CHECK_EQ(live_endpoints_->load(), 0)
      << "destroy writers and readers before their participant";
  participant_->delete_contained_entities();
  DomainParticipantFactory::get_instance()->delete_participant(participant_);
}

eprosima::fastdds::dds::Topic* Participant::find_or_create_topic(
    const std::string& topic, const eprosima::fastdds::dds::TypeSupport& type) {
  std::lock_guard<std::mutex> lock(topics_mutex_);
  if (auto it = topics_.find(topic); it != topics_.end()) {
    if (it->second->get_type_name() != type.get_type_name()) {
      throw DdsError("topic '" + topic + "' is already used with type " +
                     it->second->get_type_name() + ", not " + type.get_type_name());
    }
    return it->second;
  }
  if (type.register_type(participant_) != ReturnCode_t::RETCODE_OK) {
    throw DdsError("could not register DDS type " + type.get_type_name());
  }
  auto* created = participant_->create_topic(topic, type.get_type_name(),
                                             eprosima::fastdds::dds::TOPIC_QOS_DEFAULT);
  if (created == nullptr) throw DdsError("could not create DDS topic '" + topic + "'");
  topics_.emplace(topic, created);
  return created;
}

eprosima::fastdds::dds::DataWriter* Participant::create_writer(eprosima::fastdds::dds::Topic* topic,
                                                               const std::string& profile) {
  eprosima::fastdds::dds::DataWriterQos qos;
  if (publisher_->get_datawriter_qos_from_profile(profile, qos) != ReturnCode_t::RETCODE_OK) {
    throw DdsError("DDS profiles file '" + profiles_file_.string() +
                   "' has no <data_writer> profile named '" + profile + "' (needed for topic '" +
                   topic->get_name() + "')");
  }
  if (snapshot_rate_mb_s_ > 0.0 && profile == TopicTraits<msg::PolicySnapshot>::kWriterProfile) {
    // The form Fast DDS 2.9 also reads from XML: bytes per 10 ms period.
    constexpr std::uint32_t kPeriodMs = 10;
    const double bytes = snapshot_rate_mb_s_ * 1e6 * kPeriodMs / 1000.0;
    qos.throughput_controller(eprosima::fastrtps::rtps::ThroughputControllerDescriptor(
        static_cast<std::uint32_t>(std::max(bytes, 1024.0)), kPeriodMs));
    INDRIVE_LOG(kInfo, "dds") << "snapshot writer limited to " << snapshot_rate_mb_s_
                              << " MB/s (dds.snapshot_rate_mb_s)";
  }
  auto* writer = publisher_->create_datawriter(topic, qos);
  if (writer == nullptr) {
    throw DdsError("could not create a DDS writer on '" + topic->get_name() + "' with profile '" +
                   profile + "' (inconsistent QoS in the XML?" +
                   permissions_note(participant_->get_qos(), "publish") + ")");
  }
  return writer;
}

eprosima::fastdds::dds::DataReader* Participant::create_reader(
    eprosima::fastdds::dds::Topic* topic, const std::string& profile,
    eprosima::fastdds::dds::DataReaderListener* listener) {
  eprosima::fastdds::dds::DataReaderQos qos;
  if (subscriber_->get_datareader_qos_from_profile(profile, qos) != ReturnCode_t::RETCODE_OK) {
    throw DdsError("DDS profiles file '" + profiles_file_.string() +
                   "' has no <data_reader> profile named '" + profile + "' (needed for topic '" +
                   topic->get_name() + "')");
  }
  auto* reader = subscriber_->create_datareader(topic, qos, listener);
  if (reader == nullptr) {
    throw DdsError("could not create a DDS reader on '" + topic->get_name() + "' with profile '" +
                   profile + "' (inconsistent QoS in the XML?" +
                   permissions_note(participant_->get_qos(), "subscribe to") + ")");
  }
  return reader;
}

namespace detail {

bool wait_for_count(const std::function<int()>& current, int count,
                    std::chrono::milliseconds timeout) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (current() < count) {
    if (std::chrono::steady_clock::now() >= deadline) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  return true;
}

}  // namespace detail
}  // namespace indrive::dds
