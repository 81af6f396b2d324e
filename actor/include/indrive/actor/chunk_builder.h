// Assembles an actor's steps into TrajectoryChunks: at most L steps, one episode and one
// policy version per chunk, class-id frames zstd-compressed, sealed with a checksum.
//
//   ChunkBuilder builder({.run_id = "r", .actor_id = 0, .height = 32, .width = 32,
//                         .chunk_length = 64, .phase = msg::PHASE_PRETRAIN});
//   if (builder.add(step)) writer->write(builder.take());   // full or episode end
#pragma once

#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "indrive/msg/trajectory.h"

namespace indrive::actor {

struct ChunkBuilderOptions {
  std::string run_id;
  std::uint32_t actor_id = 0;
  int height = 0;
  int width = 0;
  int chunk_length = 64;  // L
  msg::Phase phase = msg::PHASE_PRETRAIN;
  bool with_rewards = false;  // task phases carry the extrinsic reward; pretraining never does
};

// One recorded step: the frame the actor saw and what it did then.
struct ActorStep {
  std::span<const std::uint8_t> frame;  // (H, W) class ids
  int action = 0;                       // chosen after seeing the frame; 0 on the last step
  bool is_first = false;
  bool is_last = false;
  bool is_terminal = false;
  std::uint32_t events = 0;        // EventBit bits of the step that produced the frame
  std::optional<float> reward;     // extrinsic reward; required exactly when with_rewards
  std::uint64_t episode_id = 0;    // per actor
  std::uint64_t episode_step = 0;  // step index within the episode
  std::uint64_t policy_version = 0;
};

class ChunkBuilder {
 public:
  explicit ChunkBuilder(ChunkBuilderOptions options);

  // Appends a step; returns true when the chunk is complete (L steps or the episode's last
  // step) and must be taken. A step of another episode or policy version than the open chunk
  // is a caller bug (flush first) and aborts.
  bool add(const ActorStep& step);
  // Number of steps in the open chunk.
  int size() const { return static_cast<int>(actions_.size()); }
  bool empty() const { return actions_.empty(); }
  // Policy version of the open chunk (valid when not empty).
  std::uint64_t policy_version() const { return chunk_.policy_version(); }
  // Returns the open chunk compressed and sealed, and starts the next one (chunk_seq + 1).
  // The open chunk must not be empty.
  msg::TrajectoryChunk take();
  // Sequence number the next taken chunk gets.
  std::uint64_t next_seq() const { return next_seq_; }

 private:
  ChunkBuilderOptions options_;
  msg::TrajectoryChunk chunk_;
  std::vector<std::uint8_t> frames_;  // (n, H, W)
  std::vector<std::uint8_t> actions_;
  std::uint64_t next_seq_ = 0;
};

}  // namespace indrive::actor
