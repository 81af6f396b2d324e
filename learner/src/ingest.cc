#include "indrive/learner/ingest.h"

#include <algorithm>

#include "indrive/basics/log.h"

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

dds::DropReason ChunkQueue::offer(const msg::TrajectoryChunk& chunk) {
  DecodedChunk decoded;
  dds::DropReason reason = decode_chunk(chunk, options_, decoded);
  if (reason == dds::DropReason::kOk && !stored_.first_time(chunk)) {
    reason = dds::DropReason::kDuplicate;
  }
  drops_.record(reason);
  if (reason != dds::DropReason::kOk) {
    INDRIVE_LOG(kWarn, "learner") << "dropped chunk " << chunk.chunk_seq() << " of actor "
                                  << chunk.actor_id() << " (run '" << chunk.run_id()
                                  << "'): " << dds::drop_reason_name(reason);
    return reason;
  }
  std::lock_guard<std::mutex> lock(mutex_);
  queue_.push_back(std::move(decoded));
  return reason;
}

ChunkQueue::Drained ChunkQueue::drain_into(agent::ReplayBuffer& replay,
                                           std::uint64_t policy_version) {
  std::deque<DecodedChunk> taken;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    taken.swap(queue_);
  }
  Drained drained;
  for (DecodedChunk& chunk : taken) {
    auto expected = next_seq_.find(chunk.actor_id);
    if (chunk.chunk_seq != 0 &&
        (expected == next_seq_.end() || expected->second != chunk.chunk_seq)) {
      ++drained.sequence_gaps;
      chunk.steps.front().is_first = true;
    }
    next_seq_[chunk.actor_id] = chunk.chunk_seq + 1;
    for (const auto& step : chunk.steps) replay.add(static_cast<int>(chunk.actor_id), step);
    drained.steps += static_cast<std::int64_t>(chunk.steps.size());
    ++drained.chunks;
    drained.lag_sum += static_cast<double>(policy_version - chunk.policy_version);
  }
  return drained;
}

}  // namespace indrive::learner
