// Turning received TrajectoryChunks into replay steps, or into a counted drop.
//
// Nothing foreign or corrupt may enter replay: a chunk is decoded only after the wire checks
// (schema, run id, shape, checksum; dds/messages.h) and the learner's own: frame size of this
// model, phase, rewards present exactly in task phases, action and class ids in range.
//
//   ChunkQueue queue(options);
//   queue.offer(chunk);                                      // DDS thread: checked, decoded
//   ChunkQueue::Drained d = queue.drain_into(replay, version);  // training thread: stored
#pragma once

#include <cstdint>
#include <deque>
#include <map>
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

// Chunks on their way into the replay: checked, decoded and counted on the DDS thread (offer),
// queued, and stored by the training thread (drain_into), which owns the replay. A chunk whose
// predecessor from the same actor never came starts a new piece of trajectory, so a lost chunk
// does not glue two pieces together; after a learner restart each actor's first chunk follows
// steps that were never stored, and starts a new piece as well.
class ChunkQueue {
 public:
  explicit ChunkQueue(IngestOptions options) : options_(std::move(options)) {}

  // DDS thread: decodes `chunk` and queues it; returns why it was dropped (kOk: queued). Drops
  // are counted and logged.
  dds::DropReason offer(const msg::TrajectoryChunk& chunk);

  // What one drain stored.
  struct Drained {
    std::uint64_t chunks = 0;
    std::int64_t steps = 0;
    std::uint64_t sequence_gaps = 0;  // chunks stored as the start of a new piece
    double lag_sum = 0.0;             // sum over chunks of policy_version - chunk's version
  };
  // Training thread: stores every queued chunk in `replay`.
  Drained drain_into(agent::ReplayBuffer& replay, std::uint64_t policy_version);

  const dds::DropCounters& drops() const { return drops_; }
  // Actors with a chunk stored since this process started (training thread).
  std::size_t actors() const { return next_seq_.size(); }

 private:
  IngestOptions options_;
  dds::DropCounters drops_;
  DuplicateFilter stored_;  // a chunk stored already is dropped as a duplicate
  std::mutex mutex_;
  std::deque<DecodedChunk> queue_;                   // under mutex_
  std::map<std::uint32_t, std::uint64_t> next_seq_;  // training thread
};

}  // namespace indrive::learner
