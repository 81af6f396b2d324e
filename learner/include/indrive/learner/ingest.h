// Turning received TrajectoryChunks into replay steps, or into a counted drop.
//
// Nothing foreign or corrupt may enter replay: a chunk is decoded only after the wire checks
// (schema, run id, shape, checksum; dds/messages.h) and the learner's own: frame size of this
// model, phase, rewards present exactly in task phases, action and class ids in range.
//
//   DecodedChunk decoded;
//   auto reason = decode_chunk(chunk, options, decoded);
//   if (reason != dds::DropReason::kOk) drops.record(reason); else for (auto& s : decoded.steps)
//   ...
#pragma once

#include <cstdint>
#include <deque>
#include <mutex>
#include <set>
#include <string>
#include <tuple>
#include <vector>

#include "indrive/agent/replay.h"
#include "indrive/dds/messages.h"

namespace indrive::learner {

// What a chunk must look like to be stored.
struct IngestOptions {
  std::string run_id;
  int height = 0;
  int width = 0;
  msg::Phase phase = msg::PHASE_PRETRAIN;
  bool with_rewards = false;  // task phases; pretraining chunks must carry no reward
  int num_actions = 9;
  int num_classes = 8;
};

// A chunk in replay form.
struct DecodedChunk {
  std::uint32_t actor_id = 0;
  std::uint64_t chunk_seq = 0;
  std::uint64_t episode_id = 0;
  std::uint64_t policy_version = 0;
  std::vector<agent::ReplayStep> steps;  // num_steps steps, frames (H, W) class ids each
};

// Decodes `chunk` into `out`; returns kOk, or the reason to drop it (then `out` is
// unspecified). Never throws on malformed data.
dds::DropReason decode_chunk(const msg::TrajectoryChunk& chunk, const IngestOptions& options,
                             DecodedChunk& out);

// Remembers the chunks a learner stored, so that one arriving again (a sender or a network that
// repeats a sample) is dropped as kDuplicate instead of entering replay twice. A chunk is the
// same when actor, sequence number, episode and checksum all agree: a restarted actor numbers
// its chunks from 0 again, but its frames and so its checksum differ. Holds the newest
// `capacity` chunks (far more than can be in flight). Thread-safe.
class DuplicateFilter {
 public:
  explicit DuplicateFilter(std::size_t capacity = 1 << 16) : capacity_(capacity) {}
  // True the first time a chunk is offered (it is then remembered), false for a repeat.
  bool first_time(const msg::TrajectoryChunk& chunk);

 private:
  using Key = std::tuple<std::uint32_t, std::uint64_t, std::uint64_t, std::uint32_t>;
  std::size_t capacity_;
  std::mutex mutex_;
  std::set<Key> seen_;
  std::deque<Key> order_;
};

}  // namespace indrive::learner
