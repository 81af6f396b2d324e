// Helpers around the wire contract (idl/*.idl): checksums, frame compression and validation.
//
// Every message carries schema_version and run_id; large messages carry a crc32 checksum over
// their payload. A reader validates each sample and drops-and-counts what fails, never crashes:
//
//   indrive::dds::DropCounters drops;
//   auto reason = indrive::dds::validate(chunk, run_id);
//   if (reason != indrive::dds::DropReason::kOk) { drops.record(reason); return; }
//   auto frames = indrive::dds::decompress_frames(chunk);  // (L, H, W) class ids
//
// A writer fills the fields, then calls seal(msg) to set schema_version and checksum.
#pragma once

#include <fastcdr/exceptions/Exception.h>

#include <array>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <span>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "indrive/basics/episode_csv.h"
#include "indrive/msg/common.h"
#include "indrive/msg/control.h"
#include "indrive/msg/controlPubSubTypes.h"
#include "indrive/msg/evaluation.h"
#include "indrive/msg/evaluationPubSubTypes.h"
#include "indrive/msg/policy.h"
#include "indrive/msg/policyPubSubTypes.h"
#include "indrive/msg/trajectory.h"
#include "indrive/msg/trajectoryPubSubTypes.h"

namespace indrive::dds {

// Schema version of the messages this build writes and accepts (defined once, in idl/common.idl).
inline constexpr std::uint16_t kSchemaVersion = indrive::msg::WIRE_SCHEMA_VERSION;

// Why a received message was dropped (kOk: it was not).
enum class DropReason : int {
  kOk = 0,
  kWrongSchema = 1,
  kWrongRun = 2,
  kBadShape = 3,
  kBadChecksum = 4,
  kDuplicate = 5,  // a chunk the learner already stored (learner/ingest.h, DuplicateFilter)
};
inline constexpr int kNumDropReasons = 6;

// Short lowercase name of a reason, e.g. "bad_checksum".
std::string_view drop_reason_name(DropReason reason);

// Thrown when compressed frames cannot be decoded (corrupt data or a size mismatch).
class DataError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Per-reason counts of dropped messages; safe to update from several listener threads.
class DropCounters {
 public:
  // Adds one message dropped for `reason` (kOk is counted as accepted).
  void record(DropReason reason);
  // Number of messages recorded with `reason`.
  std::uint64_t count(DropReason reason) const;
  // Number of dropped messages over all reasons (accepted ones excluded).
  std::uint64_t dropped() const;
  // One line such as
  // "accepted=10 wrong_schema=0 wrong_run=1 bad_shape=0 bad_checksum=2 duplicate=0".
  std::string summary() const;

 private:
  std::array<std::atomic<std::uint64_t>, kNumDropReasons> counts_{};
};

// crc32 over the payload of a message, as stored in its checksum field. The covered fields are
// listed in dds_messages.cc; integers and floats enter as little-endian bytes so that hosts of
// either byte order agree.
std::uint32_t compute_checksum(const msg::TrajectoryChunk& chunk);
std::uint32_t compute_checksum(const msg::PolicySnapshot& snapshot);

// Sets schema_version to kSchemaVersion and, where the type has one, the checksum field.
void seal(msg::TrajectoryChunk& chunk);
void seal(msg::PolicySnapshot& snapshot);
void seal(msg::SnapshotAnnounce& announce);
void seal(msg::SnapshotRequest& request);
void seal(msg::StepAllowance& allowance);
void seal(msg::EpisodeResult& result);
void seal(msg::Heartbeat& heartbeat);

// The sealed announcement of `snapshot` (run, version, checksum, params size), which the
// learner repeats so that late joiners notice a snapshot they missed.
msg::SnapshotAnnounce announce_for(const msg::PolicySnapshot& snapshot);

// An episode's verdict on the wire and in a results row: the fields the two share (run id,
// policy version, town, route, density, seeds, success, failure reason, steps, route completion,
// return). The sender, phase and reach are the writer's to set, the run-level columns (method,
// eval kind, task, training seed, episode index) the reader's; nothing is sealed.
void set_episode_fields(msg::EpisodeResult& result, const EpisodeRecord& record);
EpisodeRecord episode_fields(const msg::EpisodeResult& result);

// Checks schema version, run id, shape and checksum, in that order, and returns the first
// failure. An empty expected_run_id accepts any run (for tools that watch every run).
DropReason validate(const msg::TrajectoryChunk& chunk, std::string_view expected_run_id);
DropReason validate(const msg::PolicySnapshot& snapshot, std::string_view expected_run_id);
DropReason validate(const msg::SnapshotAnnounce& announce, std::string_view expected_run_id);
DropReason validate(const msg::SnapshotRequest& request, std::string_view expected_run_id);
DropReason validate(const msg::StepAllowance& allowance, std::string_view expected_run_id);
DropReason validate(const msg::EpisodeResult& result, std::string_view expected_run_id);
DropReason validate(const msg::Heartbeat& heartbeat, std::string_view expected_run_id);

// Compresses class-id frames with zstd. frames is (L, H, W) uint8, row-major. Level 3 is the
// default because on segmentation frames it measured both faster and smaller than level 1
// (common_dds_messages_bench: about 1.2 GB/s at ratio 50 against 0.8 GB/s at ratio 38).
std::vector<std::uint8_t> compress_frames(std::span<const std::uint8_t> frames, int level = 3);

// Decompresses a zstd frame that must hold exactly expected_size bytes; throws DataError when
// the data is corrupt or of another size. Returns (L, H, W) uint8 class ids.
std::vector<std::uint8_t> decompress_frames(std::span<const std::uint8_t> compressed,
                                            std::size_t expected_size);

// Decompresses chunk.frames_zstd; returns (num_steps, image_height, image_width) uint8.
std::vector<std::uint8_t> decompress_frames(const msg::TrajectoryChunk& chunk);

// Samples whose bytes did not decode as their type, over all topics of this process.
std::uint64_t undecodable_samples();
void count_undecodable_sample();

// The generated PubSubTypes catch only fastcdr's NotEnoughMemoryException while decoding. Any
// other decoding error (a first byte that is no encapsulation, a boolean other than 0 or 1)
// escaped from DataReader::take into the listener and ended the process: one bad sample from
// anyone on the domain stopped a learner (found by tests/fuzz, target chunk). This wrapper,
// registered for every topic, turns every decoding failure into `false`, which Fast DDS
// handles by dropping the sample, and counts it (undecodable_samples()).
template <typename Generated>
class GuardedPubSubType : public Generated {
 public:
  bool deserialize(eprosima::fastrtps::rtps::SerializedPayload_t* payload, void* data) override {
    try {
      if (Generated::deserialize(payload, data)) return true;
    } catch (const eprosima::fastcdr::exception::Exception&) {
    }
    count_undecodable_sample();
    return false;
  }
};

// Static description of a message type on the wire: its topic and its XML QoS profile names.
template <typename T>
struct TopicTraits;

#define INDRIVE_DDS_TOPIC(Type, topic, profile)                      \
  template <>                                                        \
  struct TopicTraits<msg::Type> {                                    \
    using PubSubType = GuardedPubSubType<msg::Type##PubSubType>;     \
    static constexpr const char* kTopic = topic;                     \
    static constexpr const char* kWriterProfile = profile "_writer"; \
    static constexpr const char* kReaderProfile = profile "_reader"; \
  };

INDRIVE_DDS_TOPIC(TrajectoryChunk, "indrive/trajectory", "trajectory")
INDRIVE_DDS_TOPIC(PolicySnapshot, "indrive/policy", "policy")
INDRIVE_DDS_TOPIC(SnapshotAnnounce, "indrive/policy_announce", "policy_announce")
INDRIVE_DDS_TOPIC(SnapshotRequest, "indrive/snapshot_request", "snapshot_request")
INDRIVE_DDS_TOPIC(StepAllowance, "indrive/allowance", "allowance")
INDRIVE_DDS_TOPIC(EpisodeResult, "indrive/episode_result", "episode_result")
INDRIVE_DDS_TOPIC(Heartbeat, "indrive/heartbeat", "heartbeat")

#undef INDRIVE_DDS_TOPIC

}  // namespace indrive::dds
