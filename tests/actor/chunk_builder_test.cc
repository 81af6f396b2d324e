#include "indrive/actor/chunk_builder.h"

#include <gtest/gtest.h>

#include "indrive/dds/messages.h"

namespace indrive::actor {
namespace {

constexpr int kSide = 8;

std::vector<std::uint8_t> frame_of(int t) {
  std::vector<std::uint8_t> frame(kSide * kSide);
  for (std::size_t i = 0; i < frame.size(); ++i) frame[i] = static_cast<std::uint8_t>((i + t) % 8);
  return frame;
}

ChunkBuilderOptions options(int length, bool rewards = false) {
  return {.run_id = "run-a",
          .actor_id = 3,
          .height = kSide,
          .width = kSide,
          .chunk_length = length,
          .phase = rewards ? msg::PHASE_FINETUNE : msg::PHASE_PRETRAIN,
          .with_rewards = rewards};
}

TEST(ChunkBuilderTest, FullChunkIsSealedAndCarriesEveryStep) {
  ChunkBuilder builder(options(4));
  std::vector<std::vector<std::uint8_t>> frames;
  for (int t = 0; t < 4; ++t) {
    frames.push_back(frame_of(t));
    const bool complete = builder.add({.frame = frames.back(),
                                       .action = t + 1,
                                       .is_first = t == 0,
                                       .events = static_cast<std::uint32_t>(t),
                                       .episode_id = 7,
                                       .episode_step = static_cast<std::uint64_t>(t),
                                       .policy_version = 5});
    EXPECT_EQ(complete, t == 3) << "step " << t;
  }
  const msg::TrajectoryChunk chunk = builder.take();
  EXPECT_EQ(dds::validate(chunk, "run-a"), dds::DropReason::kOk);
  EXPECT_EQ(chunk.num_steps(), 4u);
  EXPECT_EQ(chunk.actor_id(), 3u);
  EXPECT_EQ(chunk.episode_id(), 7u);
  EXPECT_EQ(chunk.policy_version(), 5u);
  EXPECT_EQ(chunk.chunk_seq(), 0u);
  EXPECT_TRUE(chunk.rewards().empty()) << "pretraining chunks carry no reward";
  EXPECT_EQ(chunk.flags()[0], msg::STEP_IS_FIRST);
  EXPECT_EQ(chunk.flags()[1], 0);
  EXPECT_EQ(chunk.actions()[2], 3);
  EXPECT_EQ(chunk.events()[3], 3);
  const auto decoded = dds::decompress_frames(chunk);
  ASSERT_EQ(decoded.size(), 4u * kSide * kSide);
  for (int t = 0; t < 4; ++t) {
    EXPECT_TRUE(std::equal(frames[t].begin(), frames[t].end(), decoded.begin() + t * kSide * kSide))
        << "frame " << t;
  }
  EXPECT_TRUE(builder.empty());
  EXPECT_EQ(builder.next_seq(), 1u);
}

TEST(ChunkBuilderTest, EpisodeEndClosesAShortChunkWithTerminalFlags) {
  ChunkBuilder builder(options(64, /*rewards=*/true));
  const auto frame = frame_of(0);
  EXPECT_FALSE(builder.add({.frame = frame, .reward = 0.5f, .episode_id = 1, .episode_step = 10}));
  EXPECT_TRUE(builder.add({.frame = frame,
                           .is_last = true,
                           .is_terminal = true,
                           .reward = -1.0f,
                           .episode_id = 1,
                           .episode_step = 11}));
  const auto chunk = builder.take();
  EXPECT_EQ(chunk.num_steps(), 2u);
  EXPECT_EQ(chunk.first_step(), 10u);
  EXPECT_EQ(chunk.flags()[1], msg::STEP_IS_LAST | msg::STEP_IS_TERMINAL);
  ASSERT_EQ(chunk.rewards().size(), 2u);
  EXPECT_FLOAT_EQ(chunk.rewards()[1], -1.0f);
  EXPECT_EQ(dds::validate(chunk, "run-a"), dds::DropReason::kOk);
}

TEST(ChunkBuilderTest, SequenceNumbersRiseAndAnyCorruptionFailsTheChecksum) {
  ChunkBuilder builder(options(1));
  const auto frame = frame_of(1);
  builder.add({.frame = frame, .episode_step = 0});
  const auto first = builder.take();
  builder.add({.frame = frame, .episode_step = 1});
  auto second = builder.take();
  EXPECT_EQ(first.chunk_seq() + 1, second.chunk_seq());
  second.actions()[0] ^= 1;
  EXPECT_EQ(dds::validate(second, "run-a"), dds::DropReason::kBadChecksum);
}

TEST(ChunkBuilderDeathTest, MixingPolicyVersionsInOneChunkIsABug) {
  ChunkBuilder builder(options(8));
  const auto frame = frame_of(0);
  builder.add({.frame = frame, .episode_step = 0, .policy_version = 1});
  EXPECT_DEATH(builder.add({.frame = frame, .episode_step = 1, .policy_version = 2}),
               "policy swap");
}

}  // namespace
}  // namespace indrive::actor
