#include "indrive/dds/messages.h"

#include <zstd.h>

#include <bit>
#include <cstring>
#include <memory>
#include <sstream>

#include "indrive/basics/checksum.h"

namespace indrive::dds {
namespace {

// Feeds fields to crc32 in a fixed, byte-order independent encoding: integers and floats as
// little-endian bytes, strings and sequences as their length (u32) followed by the elements.
class ChecksumBuilder {
 public:
  template <typename Int>
  void integer(Int value) {
    static_assert(std::is_integral_v<Int> || std::is_enum_v<Int>);
    std::uint8_t bytes[sizeof(Int)];
    auto raw = static_cast<std::uint64_t>(value);
    for (std::size_t i = 0; i < sizeof(Int); ++i)
      bytes[i] = static_cast<std::uint8_t>(raw >> (8 * i));
    crc_ = crc32(bytes, sizeof(Int), crc_);
  }
  void floating(double value) { integer(std::bit_cast<std::uint64_t>(value)); }
  void floating(float value) { integer(std::bit_cast<std::uint32_t>(value)); }
  void string(const std::string& text) {
    integer(static_cast<std::uint32_t>(text.size()));
    crc_ = crc32(text.data(), text.size(), crc_);
  }
  void bytes(const std::vector<std::uint8_t>& data) {
    integer(static_cast<std::uint32_t>(data.size()));
    crc_ = crc32(data.data(), data.size(), crc_);
  }
  template <typename T>
  void numbers(const std::vector<T>& data) {
    integer(static_cast<std::uint32_t>(data.size()));
    if constexpr (std::endian::native == std::endian::little) {
      crc_ = crc32(data.data(), data.size() * sizeof(T), crc_);
    } else {
      for (const T& value : data) {
        if constexpr (std::is_floating_point_v<T>) {
          floating(value);
        } else {
          integer(value);
        }
      }
    }
  }
  std::uint32_t value() const { return crc_; }

 private:
  std::uint32_t crc_ = 0;
};

DropReason check_header(std::uint16_t schema_version, const std::string& run_id,
                        std::string_view expected_run_id) {
  if (schema_version != kSchemaVersion) return DropReason::kWrongSchema;
  if (!expected_run_id.empty() && run_id != expected_run_id) return DropReason::kWrongRun;
  return DropReason::kOk;
}

struct ZstdContexts {
  std::unique_ptr<ZSTD_CCtx, decltype(&ZSTD_freeCCtx)> compress{ZSTD_createCCtx(), ZSTD_freeCCtx};
  std::unique_ptr<ZSTD_DCtx, decltype(&ZSTD_freeDCtx)> decompress{ZSTD_createDCtx(), ZSTD_freeDCtx};
};

// One context pair per thread: creating them per call costs more than compressing a chunk.
ZstdContexts& zstd_contexts() {
  thread_local ZstdContexts contexts;
  return contexts;
}

}  // namespace

namespace {
std::atomic<std::uint64_t> g_undecodable{0};
}  // namespace

std::uint64_t undecodable_samples() { return g_undecodable.load(std::memory_order_relaxed); }

void count_undecodable_sample() { g_undecodable.fetch_add(1, std::memory_order_relaxed); }

std::string_view drop_reason_name(DropReason reason) {
  switch (reason) {
    case DropReason::kOk:
      return "accepted";
    case DropReason::kWrongSchema:
      return "wrong_schema";
    case DropReason::kWrongRun:
      return "wrong_run";
    case DropReason::kBadShape:
      return "bad_shape";
    case DropReason::kBadChecksum:
      return "bad_checksum";
    case DropReason::kDuplicate:
      return "duplicate";
  }
  return "unknown";
}

void DropCounters::record(DropReason reason) {
  counts_[static_cast<int>(reason)].fetch_add(1, std::memory_order_relaxed);
}

std::uint64_t DropCounters::count(DropReason reason) const {
  return counts_[static_cast<int>(reason)].load(std::memory_order_relaxed);
}

std::uint64_t DropCounters::dropped() const {
  std::uint64_t total = 0;
  for (int i = 1; i < kNumDropReasons; ++i) total += counts_[i].load(std::memory_order_relaxed);
  return total;
}

std::string DropCounters::summary() const {
  std::ostringstream out;
  for (int i = 0; i < kNumDropReasons; ++i) {
    if (i > 0) out << ' ';
    out << drop_reason_name(static_cast<DropReason>(i)) << '=' << count(static_cast<DropReason>(i));
  }
  return out.str();
}

// Covers every field except checksum itself.
std::uint32_t compute_checksum(const msg::TrajectoryChunk& chunk) {
  ChecksumBuilder crc;
  crc.integer(chunk.schema_version());
  crc.string(chunk.run_id());
  crc.integer(chunk.actor_id());
  crc.integer(chunk.chunk_seq());
  crc.integer(chunk.episode_id());
  crc.integer(chunk.first_step());
  crc.integer(chunk.num_steps());
  crc.integer(chunk.image_height());
  crc.integer(chunk.image_width());
  crc.integer(chunk.policy_version());
  crc.integer(static_cast<std::uint32_t>(chunk.phase()));
  crc.bytes(chunk.frames_zstd());
  crc.bytes(chunk.actions());
  crc.bytes(chunk.flags());
  crc.numbers(chunk.events());
  crc.numbers(chunk.rewards());
  return crc.value();
}

// Covers every field except checksum itself.
std::uint32_t compute_checksum(const msg::PolicySnapshot& snapshot) {
  ChecksumBuilder crc;
  crc.integer(snapshot.schema_version());
  crc.string(snapshot.run_id());
  crc.integer(snapshot.version());
  crc.string(snapshot.preset());
  crc.string(snapshot.architecture());
  crc.integer(snapshot.heads());
  crc.integer(static_cast<std::uint32_t>(snapshot.phase()));
  crc.integer(snapshot.env_steps());
  crc.integer(snapshot.updates());
  crc.bytes(snapshot.params());
  return crc.value();
}

void seal(msg::TrajectoryChunk& chunk) {
  chunk.schema_version(kSchemaVersion);
  chunk.checksum(compute_checksum(chunk));
}
void seal(msg::PolicySnapshot& snapshot) {
  snapshot.schema_version(kSchemaVersion);
  snapshot.checksum(compute_checksum(snapshot));
}
void seal(msg::SnapshotAnnounce& announce) { announce.schema_version(kSchemaVersion); }
void seal(msg::SnapshotRequest& request) { request.schema_version(kSchemaVersion); }
void seal(msg::StepAllowance& allowance) { allowance.schema_version(kSchemaVersion); }
void seal(msg::EpisodeResult& result) { result.schema_version(kSchemaVersion); }
void seal(msg::Heartbeat& heartbeat) { heartbeat.schema_version(kSchemaVersion); }

msg::SnapshotAnnounce announce_for(const msg::PolicySnapshot& snapshot) {
  msg::SnapshotAnnounce announce;
  announce.run_id(snapshot.run_id());
  announce.version(snapshot.version());
  announce.checksum(snapshot.checksum());
  announce.size_bytes(snapshot.params().size());
  seal(announce);
  return announce;
}

void set_episode_fields(msg::EpisodeResult& result, const EpisodeRecord& record) {
  result.run_id(record.run_id);
  result.policy_version(static_cast<std::uint64_t>(record.policy_version));
  result.town(record.town);
  result.route(record.route);
  result.density(static_cast<std::uint32_t>(record.density));
  result.traffic_seed(static_cast<std::uint32_t>(record.traffic_seed));
  result.spawn_seed(static_cast<std::uint32_t>(record.spawn_seed));
  result.success(record.success);
  result.failure_reason(record.failure_reason);
  result.steps(static_cast<std::uint32_t>(record.steps));
  result.route_completion(static_cast<float>(record.route_completion));
  result.episode_return(static_cast<float>(record.episode_return));
}

EpisodeRecord episode_fields(const msg::EpisodeResult& result) {
  EpisodeRecord record;
  record.run_id = result.run_id();
  record.policy_version = static_cast<long long>(result.policy_version());
  record.town = result.town();
  record.route = result.route();
  record.density = static_cast<int>(result.density());
  record.traffic_seed = static_cast<int>(result.traffic_seed());
  record.spawn_seed = static_cast<int>(result.spawn_seed());
  record.success = result.success();
  record.failure_reason = result.failure_reason();
  record.steps = static_cast<int>(result.steps());
  record.route_completion = result.route_completion();
  record.episode_return = result.episode_return();
  return record;
}

DropReason validate(const msg::TrajectoryChunk& chunk, std::string_view expected_run_id) {
  if (auto header = check_header(chunk.schema_version(), chunk.run_id(), expected_run_id);
      header != DropReason::kOk) {
    return header;
  }
  const std::size_t steps = chunk.num_steps();
  if (steps == 0 || chunk.image_height() == 0 || chunk.image_width() == 0 ||
      chunk.actions().size() != steps || chunk.flags().size() != steps ||
      chunk.events().size() != steps ||
      (!chunk.rewards().empty() && chunk.rewards().size() != steps) ||
      chunk.frames_zstd().empty()) {
    return DropReason::kBadShape;
  }
  // The zstd frame header states the decompressed size: a cheap shape check before any work.
  const unsigned long long content =
      ZSTD_getFrameContentSize(chunk.frames_zstd().data(), chunk.frames_zstd().size());
  if (content != steps * chunk.image_height() * chunk.image_width()) return DropReason::kBadShape;
  if (compute_checksum(chunk) != chunk.checksum()) return DropReason::kBadChecksum;
  return DropReason::kOk;
}

DropReason validate(const msg::PolicySnapshot& snapshot, std::string_view expected_run_id) {
  if (auto header = check_header(snapshot.schema_version(), snapshot.run_id(), expected_run_id);
      header != DropReason::kOk) {
    return header;
  }
  if (snapshot.params().empty() || snapshot.architecture().empty() || snapshot.heads() == 0) {
    return DropReason::kBadShape;
  }
  if (compute_checksum(snapshot) != snapshot.checksum()) return DropReason::kBadChecksum;
  return DropReason::kOk;
}

DropReason validate(const msg::SnapshotAnnounce& announce, std::string_view expected_run_id) {
  if (auto header = check_header(announce.schema_version(), announce.run_id(), expected_run_id);
      header != DropReason::kOk) {
    return header;
  }
  if (announce.size_bytes() == 0) return DropReason::kBadShape;
  return DropReason::kOk;
}

DropReason validate(const msg::SnapshotRequest& request, std::string_view expected_run_id) {
  return check_header(request.schema_version(), request.run_id(), expected_run_id);
}

DropReason validate(const msg::StepAllowance& allowance, std::string_view expected_run_id) {
  if (auto header = check_header(allowance.schema_version(), allowance.run_id(), expected_run_id);
      header != DropReason::kOk) {
    return header;
  }
  if (!(allowance.replay_ratio() >= 0.0)) return DropReason::kBadShape;  // also rejects NaN
  return DropReason::kOk;
}

DropReason validate(const msg::EpisodeResult& result, std::string_view expected_run_id) {
  if (auto header = check_header(result.schema_version(), result.run_id(), expected_run_id);
      header != DropReason::kOk) {
    return header;
  }
  if (!(result.route_completion() >= 0.0f && result.route_completion() <= 1.0f)) {
    return DropReason::kBadShape;
  }
  return DropReason::kOk;
}

DropReason validate(const msg::Heartbeat& heartbeat, std::string_view expected_run_id) {
  return check_header(heartbeat.schema_version(), heartbeat.run_id(), expected_run_id);
}

std::vector<std::uint8_t> compress_frames(std::span<const std::uint8_t> frames, int level) {
  std::vector<std::uint8_t> out(ZSTD_compressBound(frames.size()));
  const std::size_t size = ZSTD_compressCCtx(zstd_contexts().compress.get(), out.data(), out.size(),
                                             frames.data(), frames.size(), level);
  // Compression into a buffer of compressBound size cannot fail on valid input.
  if (ZSTD_isError(size)) {
    throw DataError(std::string("zstd compression failed: ") + ZSTD_getErrorName(size));
  }
  out.resize(size);
  return out;
}

std::vector<std::uint8_t> decompress_frames(std::span<const std::uint8_t> compressed,
                                            std::size_t expected_size) {
  const unsigned long long content = ZSTD_getFrameContentSize(compressed.data(), compressed.size());
  if (content == ZSTD_CONTENTSIZE_ERROR) {
    throw DataError("compressed frames are not a zstd frame (corrupt message?)");
  }
  if (content != ZSTD_CONTENTSIZE_UNKNOWN && content != expected_size) {
    throw DataError("compressed frames hold " + std::to_string(content) + " bytes, expected " +
                    std::to_string(expected_size) + " (L * H * W)");
  }
  std::vector<std::uint8_t> out(expected_size);
  const std::size_t size = ZSTD_decompressDCtx(zstd_contexts().decompress.get(), out.data(),
                                               out.size(), compressed.data(), compressed.size());
  if (ZSTD_isError(size)) {
    throw DataError(std::string("zstd decompression failed: ") + ZSTD_getErrorName(size));
  }
  if (size != expected_size) {
    throw DataError("compressed frames decoded to " + std::to_string(size) + " bytes, expected " +
                    std::to_string(expected_size));
  }
  return out;
}

std::vector<std::uint8_t> decompress_frames(const msg::TrajectoryChunk& chunk) {
  const std::size_t expected =
      static_cast<std::size_t>(chunk.num_steps()) * chunk.image_height() * chunk.image_width();
  return decompress_frames(chunk.frames_zstd(), expected);
}

}  // namespace indrive::dds
