#include "indrive/actor/chunk_builder.h"

#include "indrive/basics/check.h"
#include "indrive/dds/messages.h"

namespace indrive::actor {

ChunkBuilder::ChunkBuilder(ChunkBuilderOptions options) : options_(std::move(options)) {
  INDRIVE_CHECK(options_.height > 0 && options_.width > 0 && options_.chunk_length > 0)
      << "chunk builder needs a positive frame size and chunk length";
}

bool ChunkBuilder::add(const ActorStep& step) {
  const std::size_t pixels = static_cast<std::size_t>(options_.height) * options_.width;
  INDRIVE_CHECK_EQ(step.frame.size(), pixels) << "frame of the wrong size";
  INDRIVE_CHECK(step.action >= 0 && step.action < 256) << "action " << step.action;
  INDRIVE_CHECK(step.reward.has_value() == options_.with_rewards)
      << "a reward belongs in a chunk exactly in task phases";
  if (empty()) {
    chunk_ = msg::TrajectoryChunk();
    chunk_.run_id(options_.run_id);
    chunk_.actor_id(options_.actor_id);
    chunk_.episode_id(step.episode_id);
    chunk_.first_step(step.episode_step);
    chunk_.image_height(static_cast<std::uint16_t>(options_.height));
    chunk_.image_width(static_cast<std::uint16_t>(options_.width));
    chunk_.policy_version(step.policy_version);
    chunk_.phase(options_.phase);
    frames_.clear();
  } else {
    INDRIVE_CHECK_EQ(step.episode_id, chunk_.episode_id()) << "flush the chunk at episode end";
    INDRIVE_CHECK_EQ(step.policy_version, chunk_.policy_version())
        << "flush the chunk before a policy swap";
    INDRIVE_CHECK_EQ(step.episode_step, chunk_.first_step() + actions_.size())
        << "steps must be consecutive";
  }
  frames_.insert(frames_.end(), step.frame.begin(), step.frame.end());
  actions_.push_back(static_cast<std::uint8_t>(step.action));
  std::uint8_t flags = 0;
  if (step.is_first) flags |= msg::STEP_IS_FIRST;
  if (step.is_last) flags |= msg::STEP_IS_LAST;
  if (step.is_terminal) flags |= msg::STEP_IS_TERMINAL;
  chunk_.flags().push_back(flags);
  chunk_.events().push_back(static_cast<std::uint16_t>(step.events));
  if (step.reward) chunk_.rewards().push_back(*step.reward);
  return step.is_last || size() >= options_.chunk_length;
}

msg::TrajectoryChunk ChunkBuilder::take() {
  INDRIVE_CHECK(!empty()) << "no steps to send";
  chunk_.num_steps(static_cast<std::uint32_t>(actions_.size()));
  chunk_.chunk_seq(next_seq_++);
  chunk_.frames_zstd(dds::compress_frames(frames_));
  chunk_.actions(actions_);
  dds::seal(chunk_);
  msg::TrajectoryChunk done = std::move(chunk_);
  chunk_ = msg::TrajectoryChunk();
  actions_.clear();
  frames_.clear();
  return done;
}

}  // namespace indrive::actor
