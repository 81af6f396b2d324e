// Turning received TrajectoryChunks into replay steps, or into a counted drop.
//
// Nothing foreign or corrupt may enter replay: a chunk is decoded only after the wire checks
// (schema, run id, shape, checksum; dds_messages.h) and the learner's own: frame size of this
// model, phase, rewards present exactly in task phases, action and class ids in range.
//
//   DecodedChunk decoded;
//   auto reason = decode_chunk(chunk, options, decoded);
//   if (reason != dds::DropReason::kOk) drops.record(reason); else for (auto& s : decoded.steps)
//   ...
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "indrive/common/agent/replay.h"
#include "indrive/common/dds_messages.h"

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

}  // namespace indrive::learner
