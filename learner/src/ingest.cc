#include "indrive/learner/ingest.h"

#include <algorithm>

namespace indrive::learner {

dds::DropReason decode_chunk(const msg::TrajectoryChunk& chunk, const IngestOptions& options,
                             DecodedChunk& out) {
  const dds::DropReason wire = dds::validate(chunk, options.run_id);
  if (wire != dds::DropReason::kOk) return wire;
  // The learner's own shape rules: this model's frame size, this phase, rewards by phase.
  if (chunk.image_height() != options.height || chunk.image_width() != options.width ||
      chunk.phase() != options.phase ||
      (options.with_rewards ? chunk.rewards().size() != chunk.num_steps()
                            : !chunk.rewards().empty())) {
    return dds::DropReason::kBadShape;
  }
  const auto& actions = chunk.actions();
  if (std::any_of(actions.begin(), actions.end(),
                  [&](std::uint8_t a) { return a >= options.num_actions; })) {
    return dds::DropReason::kBadShape;
  }
  std::vector<std::uint8_t> frames;
  try {
    frames = dds::decompress_frames(chunk);
  } catch (const dds::DataError&) {
    return dds::DropReason::kBadShape;
  }
  if (std::any_of(frames.begin(), frames.end(),
                  [&](std::uint8_t id) { return id >= options.num_classes; })) {
    return dds::DropReason::kBadShape;
  }

  out.actor_id = chunk.actor_id();
  out.chunk_seq = chunk.chunk_seq();
  out.episode_id = chunk.episode_id();
  out.policy_version = chunk.policy_version();
  out.steps.resize(chunk.num_steps());
  const std::size_t pixels = static_cast<std::size_t>(options.height) * options.width;
  for (std::size_t t = 0; t < out.steps.size(); ++t) {
    agent::ReplayStep& step = out.steps[t];
    step.frame.assign(frames.begin() + t * pixels, frames.begin() + (t + 1) * pixels);
    step.action = actions[t];
    const std::uint8_t flags = chunk.flags()[t];
    step.is_first = (flags & msg::STEP_IS_FIRST) != 0;
    step.is_last = (flags & msg::STEP_IS_LAST) != 0;
    step.is_terminal = (flags & msg::STEP_IS_TERMINAL) != 0;
    step.reward = options.with_rewards ? chunk.rewards()[t] : 0.0f;
  }
  return dds::DropReason::kOk;
}

bool DuplicateFilter::first_time(const msg::TrajectoryChunk& chunk) {
  const Key key{chunk.actor_id(), chunk.chunk_seq(), chunk.episode_id(), chunk.checksum()};
  std::lock_guard<std::mutex> lock(mutex_);
  if (!seen_.insert(key).second) return false;
  order_.push_back(key);
  if (order_.size() > capacity_) {
    seen_.erase(order_.front());
    order_.pop_front();
  }
  return true;
}

}  // namespace indrive::learner
