// A small RAII layer over Fast DDS 2.9: one participant per process, typed writers and readers
// whose QoS comes from XML profiles by name (deploy/dds/*.xml), never from code.
//
//   indrive::dds::Participant participant({.domain_id = 7, .profiles_file = flags.dds_profiles});
//   auto writer = participant.make_writer<indrive::msg::PolicySnapshot>();
//   auto reader = participant.make_reader<indrive::msg::TrajectoryChunk>(
//       [&](const indrive::msg::TrajectoryChunk& chunk) { ... });   // on a DDS thread
//   indrive::dds::seal(snapshot);
//   writer->write(snapshot);
//
// Topic names and profile names default to TopicTraits<T> (messages.h). Writers and
// readers must be destroyed before their participant. Setup failures throw DdsError with a
// message that says what to fix; Fast DDS's own log lines go to the project's log sink.
#pragma once

#include <atomic>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <fastdds/dds/domain/DomainParticipant.hpp>
#include <fastdds/dds/publisher/DataWriter.hpp>
#include <fastdds/dds/publisher/Publisher.hpp>
#include <fastdds/dds/subscriber/DataReader.hpp>
#include <fastdds/dds/subscriber/DataReaderListener.hpp>
#include <fastdds/dds/subscriber/SampleInfo.hpp>
#include <fastdds/dds/subscriber/Subscriber.hpp>
#include <fastdds/dds/topic/Topic.hpp>
#include <fastdds/dds/topic/TypeSupport.hpp>
#include <filesystem>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "indrive/basics/log.h"
#include "indrive/dds/messages.h"
#include "indrive/dds/peers.h"

namespace indrive::config {
class Config;
class Schema;
}  // namespace indrive::config

namespace indrive::dds {

// A DDS entity could not be set up (bad profiles file, unknown profile, domain, ...).
class DdsError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Name of the environment variable Fast DDS reads its default XML profiles file from.
inline constexpr const char* kProfilesEnvVar = "FASTRTPS_DEFAULT_PROFILES_FILE";

// Name of the environment variable that gives the discovery server's HOST:PORT when neither
// the --discovery-server flag nor the dds.discovery_server key does.
inline constexpr const char* kDiscoveryServerEnvVar = "INDRIVE_DISCOVERY_SERVER";

// Port of a discovery server when HOST is given without one (Fast DDS's default).
inline constexpr int kDefaultDiscoveryPort = 11811;

struct ParticipantOptions {
  int domain_id = 0;
  // XML profiles file; empty means the file named by FASTRTPS_DEFAULT_PROFILES_FILE.
  std::string profiles_file{};
  // <participant> profile in that file.
  std::string participant_profile = "indrive_participant";
  // HOST:PORT (or HOST) of the discovery server, replacing the address the profile names;
  // the profile must be a discovery-server client (deploy/dds/discovery_server.xml). Empty:
  // $INDRIVE_DISCOVERY_SERVER, and when that is unset too, the profile's own address.
  std::string discovery_server{};
  // Folder made by deploy/dds/make_security.sh; empty: no DDS Security (security.h).
  std::string security_dir{};
  // Role whose certificate and permissions the participant uses with security_dir.
  std::string security_role{};
  // Throughput limit of the policy snapshot writer in MB/s, replacing the profile's (its
  // <throughputController>); 0 keeps the profile's. Below the rate of the slowest link that
  // snapshots cross: faster bursts overflow that link's queue and no snapshot arrives whole.
  double snapshot_rate_mb_s = 0.0;
};

// A discovery server's address: `host` as given, `ipv4` the address it resolved to, and
// where it was given (the flag or the environment variable).
struct ServerAddress {
  std::string host;
  std::string ipv4;
  int port = kDefaultDiscoveryPort;
  std::string source;
  // "HOST:PORT", with " (IP)" when HOST is a name, and " from SOURCE".
  std::string describe() const;
};

// Parses "HOST:PORT" or "HOST" and resolves HOST (a name or a dotted IPv4 address) to IPv4;
// throws DdsError naming `source` (the flag or variable it came from) when it cannot.
ServerAddress parse_discovery_server(const std::string& text, const std::string& source);

// The discovery server a participant uses: `configured` (ParticipantOptions::discovery_server)
// if not empty, else $INDRIVE_DISCOVERY_SERVER; nullopt when neither names one.
std::optional<ServerAddress> resolve_discovery_server(const std::string& configured);

// Declares the dds.* configuration keys (domain_id, profiles_file, participant_profile).
void declare_config(config::Schema& schema);

// Participant options from the dds.* keys of a resolved config.
ParticipantOptions participant_options(const config::Config& config);

// The command-line flag that names the profiles file, as an alias of dds.profiles_file for
// config::parse_command_line.
inline const std::pair<std::string, std::string> kProfilesFlag{"--dds-profiles",
                                                               "dds.profiles_file"};

// Returns the profiles file to load: explicit_path if not empty, else the environment
// variable's value; throws DdsError when neither is set or the file does not exist.
std::filesystem::path resolve_profiles_file(const std::string& explicit_path);

// Participant ids a shared-memory-only participant is given, from 0 to
// kSharedMemoryParticipantIds - 1 (kept low so the port numbers derived from them fit the
// highest domain, 232).
inline constexpr int kSharedMemoryParticipantIds = 50;

// The participant id of the `created_before`-th shared-memory-only participant of process `pid`
// (counted from 0). Fast DDS's automatic id is the lowest free one, so a process restarted
// after a kill -9, or a participant recreated to rejoin, takes the port of the one that died;
// a peer that had written to the dead port keeps its broken handle to it (it is marked not ok
// and replaced under the peer's feet) and never reaches the new participant. Ids that start at
// a hash of the pid and move with the count make that unlikely (a restarted process, or a
// replacement in another process, takes a given earlier id in about 1 case of
// kSharedMemoryParticipantIds; processes with consecutive pids do not follow each other's ids);
// Fast DDS moves a taken id on to the next free port.
int shared_memory_participant_id(long pid, int created_before);

// Routes Fast DDS's log output to the project's log sink (category "fastdds"); idempotent.
void route_fastdds_log();

// Typed writer for one topic. Create it with Participant::make_writer.
template <typename T>
class Writer {
 public:
  Writer(eprosima::fastdds::dds::Publisher* publisher, eprosima::fastdds::dds::DataWriter* writer,
         std::shared_ptr<std::atomic<int>> live_endpoints)
      : publisher_(publisher), writer_(writer), live_endpoints_(std::move(live_endpoints)) {
    live_endpoints_->fetch_add(1);
  }
  ~Writer() {
    publisher_->delete_datawriter(writer_);
    live_endpoints_->fetch_sub(1);
  }
  Writer(const Writer&) = delete;
  Writer& operator=(const Writer&) = delete;

  // Publishes one sample; returns false when it could not be queued, e.g. a KEEP_ALL history
  // is full because readers have not acknowledged enough yet (back-pressure): retry later.
  bool write(const T& sample) { return writer_->write(const_cast<T*>(&sample)); }

  // Number of readers currently matched.
  int matched() const {
    eprosima::fastdds::dds::PublicationMatchedStatus status;
    writer_->get_publication_matched_status(status);
    return status.current_count;
  }

  // Waits until at least `count` readers are matched; false on timeout.
  bool wait_for_matched(int count, std::chrono::milliseconds timeout) const;

  // Waits until every matched reliable reader acknowledged every sample; false on timeout.
  bool wait_for_acknowledgments(std::chrono::milliseconds timeout) const {
    return writer_->wait_for_acknowledgments(to_duration(timeout)) ==
           eprosima::fastrtps::types::ReturnCode_t::RETCODE_OK;
  }

  // The underlying Fast DDS writer, for what this wrapper does not cover.
  eprosima::fastdds::dds::DataWriter* native() { return writer_; }

 private:
  static eprosima::fastrtps::Duration_t to_duration(std::chrono::milliseconds timeout) {
    return eprosima::fastrtps::Duration_t(static_cast<double>(timeout.count()) / 1000.0);
  }
  eprosima::fastdds::dds::Publisher* publisher_;
  eprosima::fastdds::dds::DataWriter* writer_;
  std::shared_ptr<std::atomic<int>> live_endpoints_;
};

// Typed reader for one topic that calls a function for each sample as it arrives (on a Fast
// DDS thread; the function must be thread-safe with respect to the caller's other threads).
// Create it with Participant::make_reader.
template <typename T>
class Reader : public eprosima::fastdds::dds::DataReaderListener {
 public:
  using Callback = std::function<void(const T&)>;

  explicit Reader(Callback callback) : callback_(std::move(callback)) {}
  ~Reader() override {
    if (reader_ != nullptr) {
      reader_->set_listener(nullptr);
      subscriber_->delete_datareader(reader_);
      live_endpoints_->fetch_sub(1);
    }
  }
  Reader(const Reader&) = delete;
  Reader& operator=(const Reader&) = delete;

  // Number of writers currently matched.
  int matched() const {
    eprosima::fastdds::dds::SubscriptionMatchedStatus status;
    reader_->get_subscription_matched_status(status);
    return status.current_count;
  }

  // Waits until at least `count` writers are matched; false on timeout.
  bool wait_for_matched(int count, std::chrono::milliseconds timeout) const;

  // Samples whose callback threw; they are logged and skipped, never propagated.
  std::uint64_t callback_failures() const { return callback_failures_.load(); }

  // The underlying Fast DDS reader, for what this wrapper does not cover.
  eprosima::fastdds::dds::DataReader* native() { return reader_; }

  // Takes every available sample and hands each valid one to the callback.
  void on_data_available(eprosima::fastdds::dds::DataReader* reader) override {
    std::lock_guard<std::mutex> lock(take_mutex_);
    eprosima::fastdds::dds::SampleInfo info;
    while (reader->take_next_sample(&sample_, &info) ==
           eprosima::fastrtps::types::ReturnCode_t::RETCODE_OK) {
      if (!info.valid_data) continue;
      try {
        callback_(sample_);
      } catch (const std::exception& error) {
        callback_failures_.fetch_add(1);
        INDRIVE_LOG(kError, "dds")
            << "reader callback failed on " << reader->get_topicdescription()->get_name() << ": "
            << error.what();
      }
    }
  }

 private:
  friend class Participant;
  void attach(eprosima::fastdds::dds::Subscriber* subscriber,
              eprosima::fastdds::dds::DataReader* reader,
              std::shared_ptr<std::atomic<int>> live_endpoints) {
    subscriber_ = subscriber;
    reader_ = reader;
    live_endpoints_ = std::move(live_endpoints);
    live_endpoints_->fetch_add(1);
  }

  Callback callback_;
  eprosima::fastdds::dds::Subscriber* subscriber_ = nullptr;
  eprosima::fastdds::dds::DataReader* reader_ = nullptr;
  std::shared_ptr<std::atomic<int>> live_endpoints_;
  std::mutex take_mutex_;
  T sample_;  // reused, so its sequences keep their capacity between samples
  std::atomic<std::uint64_t> callback_failures_{0};
};

// One DomainParticipant with one Publisher and one Subscriber.
class Participant {
 public:
  // Loads the profiles file and creates the participant; throws DdsError on failure.
  explicit Participant(const ParticipantOptions& options);
  ~Participant();
  Participant(const Participant&) = delete;
  Participant& operator=(const Participant&) = delete;

  // Creates a writer on `topic` with the QoS of the XML <data_writer> profile `profile`.
  template <typename T>
  std::unique_ptr<Writer<T>> make_writer(
      const std::string& topic = TopicTraits<T>::kTopic,
      const std::string& profile = TopicTraits<T>::kWriterProfile) {
    auto* topic_entity = find_or_create_topic<T>(topic);
    return std::make_unique<Writer<T>>(publisher_, create_writer(topic_entity, profile),
                                       live_endpoints_);
  }

  // Creates a reader on `topic` with the QoS of the XML <data_reader> profile `profile`;
  // on_sample is called for every sample taken.
  template <typename T>
  std::unique_ptr<Reader<T>> make_reader(
      typename Reader<T>::Callback on_sample, const std::string& topic = TopicTraits<T>::kTopic,
      const std::string& profile = TopicTraits<T>::kReaderProfile) {
    auto* topic_entity = find_or_create_topic<T>(topic);
    auto reader = std::make_unique<Reader<T>>(std::move(on_sample));
    reader->attach(subscriber_, create_reader(topic_entity, profile, reader.get()),
                   live_endpoints_);
    return reader;
  }

  // The profiles file this participant was configured from.
  const std::filesystem::path& profiles_file() const { return profiles_file_; }
  int domain_id() const { return domain_id_; }
  // Whether the profile gives this participant a shared-memory transport (explicitly or through
  // Fast DDS's builtin transports).
  bool uses_shared_memory() const { return uses_shared_memory_; }
  // The participant id given to Fast DDS (-1: Fast DDS picks the lowest free one), see
  // shared_memory_participant_id().
  int participant_id() const { return participant_id_; }
  // The underlying Fast DDS participant, for what this wrapper does not cover.
  eprosima::fastdds::dds::DomainParticipant* native() { return participant_; }
  // This participant's GUID prefix as Fast DDS prints it (the name other participants' logs
  // give it).
  std::string guid_prefix() const;
  // The other participants of its domain: discovered, authenticated, refused, with a handshake
  // pending (peers.h). With DDS Security each authentication and refusal is logged, and a
  // handshake still pending kHandshakeStallS after discovery is warned about once.
  PeerLedger::Counts peers() const { return peers_.counts(); }
  static constexpr double kHandshakeStallS = 30.0;

 private:
  template <typename T>
  eprosima::fastdds::dds::Topic* find_or_create_topic(const std::string& topic) {
    eprosima::fastdds::dds::TypeSupport type(new typename TopicTraits<T>::PubSubType());
    return find_or_create_topic(topic, type);
  }
  eprosima::fastdds::dds::Topic* find_or_create_topic(
      const std::string& topic, const eprosima::fastdds::dds::TypeSupport& type);
  eprosima::fastdds::dds::DataWriter* create_writer(eprosima::fastdds::dds::Topic* topic,
                                                    const std::string& profile);
  eprosima::fastdds::dds::DataReader* create_reader(
      eprosima::fastdds::dds::Topic* topic, const std::string& profile,
      eprosima::fastdds::dds::DataReaderListener* listener);

  std::filesystem::path profiles_file_;
  double snapshot_rate_mb_s_ = 0.0;
  int domain_id_ = 0;
  bool uses_shared_memory_ = false;
  int participant_id_ = -1;
  PeerLedger peers_;
  // Feeds peers_ from Fast DDS's callbacks; outlives participant_.
  std::unique_ptr<eprosima::fastdds::dds::DomainParticipantListener> listener_;
  eprosima::fastdds::dds::DomainParticipant* participant_ = nullptr;
  // With DDS Security: wakes once a second to warn about stalled handshakes.
  std::jthread stall_watch_;
  eprosima::fastdds::dds::Publisher* publisher_ = nullptr;
  eprosima::fastdds::dds::Subscriber* subscriber_ = nullptr;
  std::mutex topics_mutex_;
  std::map<std::string, eprosima::fastdds::dds::Topic*> topics_;
  // Writers and readers alive on this participant; it must outlive them.
  std::shared_ptr<std::atomic<int>> live_endpoints_ = std::make_shared<std::atomic<int>>(0);
};

// A participant with the readers and writers a process made on it, torn down in the one safe
// order: every reader first, newest first, so that no callback runs into an owner being
// destroyed; then every writer; then the participant, which must outlive its endpoints. A
// process keeps one set, replaces it as a whole (a rejoin) and never lists its endpoints twice.
//
//   dds::EndpointSet dds(config.participant_options("actor"));
//   dds::Writer<msg::TrajectoryChunk>& chunks = dds.writer<msg::TrajectoryChunk>();
//   dds.reader<msg::PolicySnapshot>([this](const msg::PolicySnapshot& s) { inbox.offer(s); });
//   dds.close();  // or let it go out of scope
class EndpointSet {
 public:
  // Creates the participant; throws DdsError on failure.
  explicit EndpointSet(const ParticipantOptions& options)
      : participant_(std::make_unique<Participant>(options)) {}
  ~EndpointSet() { close(); }
  EndpointSet(const EndpointSet&) = delete;
  EndpointSet& operator=(const EndpointSet&) = delete;

  // A writer on `topic`, owned by the set and valid until close().
  template <typename T>
  Writer<T>& writer(const std::string& topic = TopicTraits<T>::kTopic,
                    const std::string& profile = TopicTraits<T>::kWriterProfile) {
    std::shared_ptr<Writer<T>> made = participant().make_writer<T>(topic, profile);
    writers_.push_back(made);
    return *made;
  }
  // A reader on `topic` calling `on_sample` for each sample, owned by the set.
  template <typename T>
  Reader<T>& reader(typename Reader<T>::Callback on_sample,
                    const std::string& topic = TopicTraits<T>::kTopic,
                    const std::string& profile = TopicTraits<T>::kReaderProfile) {
    std::shared_ptr<Reader<T>> made =
        participant().make_reader<T>(std::move(on_sample), topic, profile);
    readers_.push_back(made);
    return *made;
  }

  Participant& participant() { return *participant_; }
  const Participant& participant() const { return *participant_; }

  // Readers (newest first), then writers, then the participant; a second call does nothing.
  void close() {
    while (!readers_.empty()) readers_.pop_back();
    while (!writers_.empty()) writers_.pop_back();
    participant_.reset();
  }

 private:
  std::unique_ptr<Participant> participant_;
  // Type-erased owners: each deletes its Writer<T> or Reader<T> with the right type.
  std::vector<std::shared_ptr<void>> writers_;
  std::vector<std::shared_ptr<void>> readers_;
};

namespace detail {
// Polls `current()` until it reaches `count` or the timeout passes.
bool wait_for_count(const std::function<int()>& current, int count,
                    std::chrono::milliseconds timeout);
}  // namespace detail

template <typename T>
bool Writer<T>::wait_for_matched(int count, std::chrono::milliseconds timeout) const {
  return detail::wait_for_count([this] { return matched(); }, count, timeout);
}

template <typename T>
bool Reader<T>::wait_for_matched(int count, std::chrono::milliseconds timeout) const {
  return detail::wait_for_count([this] { return matched(); }, count, timeout);
}

}  // namespace indrive::dds
