#include "indrive/learner/ingest.h"

#include <gtest/gtest.h>

#include "indrive/actor/chunk_builder.h"

namespace indrive::learner {
namespace {

constexpr int kSide = 8;

msg::TrajectoryChunk make_chunk(int steps, bool rewards = false, std::uint8_t class_id = 3) {
  actor::ChunkBuilder builder({.run_id = "run-a",
                               .actor_id = 1,
                               .height = kSide,
                               .width = kSide,
                               .chunk_length = steps,
                               .phase = rewards ? msg::PHASE_FINETUNE : msg::PHASE_PRETRAIN,
                               .with_rewards = rewards});
  for (int t = 0; t < steps; ++t) {
    std::vector<std::uint8_t> frame(kSide * kSide, class_id);
    frame[t] = 1;
    std::optional<float> reward;
    if (rewards) reward = 0.25f * t;
    builder.add({.frame = frame,
                 .action = t % 9,
                 .is_first = t == 0,
                 .is_last = t == steps - 1,
                 .is_terminal = t == steps - 1,
                 .reward = reward,
                 .episode_id = 2,
                 .episode_step = static_cast<std::uint64_t>(t),
                 .policy_version = 9});
  }
  return builder.take();
}

IngestOptions pretrain_options() {
  return {.run_id = "run-a", .height = kSide, .width = kSide, .phase = msg::PHASE_PRETRAIN};
}

TEST(IngestTest, DecodesEveryStepAsTheActorRecordedIt) {
  DecodedChunk decoded;
  ASSERT_EQ(decode_chunk(make_chunk(5), pretrain_options(), decoded), dds::DropReason::kOk);
  EXPECT_EQ(decoded.actor_id, 1u);
  EXPECT_EQ(decoded.policy_version, 9u);
  ASSERT_EQ(decoded.steps.size(), 5u);
  for (int t = 0; t < 5; ++t) {
    const auto& step = decoded.steps[t];
    EXPECT_EQ(step.action, t % 9);
    EXPECT_EQ(step.frame[t], 1);
    EXPECT_EQ(step.frame[(t + 1) % (kSide * kSide)], 3);
    EXPECT_EQ(step.is_first, t == 0);
    EXPECT_EQ(step.is_last, t == 4);
    EXPECT_EQ(step.is_terminal, t == 4);
    EXPECT_EQ(step.reward, 0.0f);
  }
}

TEST(IngestTest, TaskChunksCarryTheirRewards) {
  auto options = pretrain_options();
  options.phase = msg::PHASE_FINETUNE;
  options.with_rewards = true;
  DecodedChunk decoded;
  ASSERT_EQ(decode_chunk(make_chunk(4, true), options, decoded), dds::DropReason::kOk);
  EXPECT_FLOAT_EQ(decoded.steps[3].reward, 0.75f);
}

TEST(IngestTest, ForeignCorruptAndMisshapenChunksAreDroppedWithTheirReason) {
  DecodedChunk decoded;
  auto options = pretrain_options();

  auto foreign = make_chunk(3);
  foreign.run_id("run-b");
  dds::seal(foreign);
  EXPECT_EQ(decode_chunk(foreign, options, decoded), dds::DropReason::kWrongRun);

  auto corrupt = make_chunk(3);
  corrupt.frames_zstd()[corrupt.frames_zstd().size() / 2] ^= 0x55;
  EXPECT_EQ(decode_chunk(corrupt, options, decoded), dds::DropReason::kBadChecksum);

  auto old_schema = make_chunk(3);
  old_schema.schema_version(old_schema.schema_version() + 1);
  EXPECT_EQ(decode_chunk(old_schema, options, decoded), dds::DropReason::kWrongSchema);

  auto other_size = options;
  other_size.height = other_size.width = 16;
  EXPECT_EQ(decode_chunk(make_chunk(3), other_size, decoded), dds::DropReason::kBadShape);

  // A reward in a pretraining chunk, and a task chunk without rewards.
  EXPECT_EQ(decode_chunk(make_chunk(3, true), options, decoded), dds::DropReason::kBadShape);
  auto task = options;
  task.with_rewards = true;
  task.phase = msg::PHASE_FINETUNE;
  auto no_reward = make_chunk(3);
  no_reward.phase(msg::PHASE_FINETUNE);
  dds::seal(no_reward);
  EXPECT_EQ(decode_chunk(no_reward, task, decoded), dds::DropReason::kBadShape);

  auto bad_action = make_chunk(3);
  bad_action.actions()[1] = 9;
  dds::seal(bad_action);
  EXPECT_EQ(decode_chunk(bad_action, options, decoded), dds::DropReason::kBadShape);

  EXPECT_EQ(decode_chunk(make_chunk(3, false, /*class_id=*/8), options, decoded),
            dds::DropReason::kBadShape);
}

// Sizes a chunk claims are checked against what it carries before anything is allocated.
TEST(IngestTest, ChunksClaimingMoreThanTheyCarryAreRejectedBeforeDecompressing) {
  DecodedChunk decoded;
  auto many_steps = make_chunk(3);
  many_steps.num_steps(1000000000u);  // a billion frames in three steps' arrays
  dds::seal(many_steps);
  EXPECT_EQ(decode_chunk(many_steps, pretrain_options(), decoded), dds::DropReason::kBadShape);

  // A zstd frame that holds more than L * H * W (its header says so) is not decompressed.
  auto bigger = make_chunk(3);
  bigger.frames_zstd() = dds::compress_frames(std::vector<std::uint8_t>(300 * kSide * kSide, 3));
  dds::seal(bigger);
  EXPECT_EQ(decode_chunk(bigger, pretrain_options(), decoded), dds::DropReason::kBadShape);
}

TEST(DuplicateFilterTest, ARepeatedChunkIsCaughtAndARestartedActorsChunksAreNot) {
  DuplicateFilter filter(/*capacity=*/3);
  const auto chunk = make_chunk(5);
  EXPECT_TRUE(filter.first_time(chunk));
  EXPECT_FALSE(filter.first_time(chunk)) << "the same chunk again";
  // A restarted actor numbers from 0 again, with other frames: the checksum tells it apart.
  const auto other = make_chunk(5, false, /*class_id=*/4);
  ASSERT_EQ(other.chunk_seq(), chunk.chunk_seq());
  EXPECT_TRUE(filter.first_time(other));
  // Only the newest `capacity` are remembered.
  EXPECT_TRUE(filter.first_time(make_chunk(4)));
  EXPECT_TRUE(filter.first_time(make_chunk(3)));
  EXPECT_TRUE(filter.first_time(chunk)) << "forgotten after three newer ones";
}

// Chunks 0..count-1 of one actor, each of `steps` steps.
std::vector<msg::TrajectoryChunk> actor_chunks(int count, int steps) {
  actor::ChunkBuilder builder({.run_id = "run-a",
                               .actor_id = 4,
                               .height = kSide,
                               .width = kSide,
                               .chunk_length = steps,
                               .phase = msg::PHASE_PRETRAIN,
                               .with_rewards = false});
  std::vector<msg::TrajectoryChunk> chunks;
  for (int c = 0; c < count; ++c) {
    for (int t = 0; t < steps; ++t) {
      builder.add({.frame = std::vector<std::uint8_t>(kSide * kSide, 3),
                   .action = t % 9,
                   .is_first = c == 0 && t == 0,
                   .episode_id = 1,
                   .episode_step = static_cast<std::uint64_t>(c * steps + t),
                   .policy_version = 5});
    }
    chunks.push_back(builder.take());
  }
  return chunks;
}

TEST(ChunkQueueTest, StoresChunksDropsRepeatsAndStartsANewPieceAfterAGap) {
  ChunkQueue queue(pretrain_options());
  agent::ReplayBuffer replay({.capacity = 1000, .height = kSide, .width = kSide});
  const auto chunks = actor_chunks(3, 4);
  EXPECT_EQ(queue.offer(chunks[0]), dds::DropReason::kOk);
  EXPECT_EQ(queue.offer(chunks[0]), dds::DropReason::kDuplicate);
  EXPECT_EQ(queue.offer(chunks[2]), dds::DropReason::kOk);  // chunk 1 never comes
  msg::TrajectoryChunk foreign = chunks[1];
  foreign.run_id("run-b");
  EXPECT_EQ(queue.offer(foreign), dds::DropReason::kWrongRun);

  const ChunkQueue::Drained drained = queue.drain_into(replay, /*policy_version=*/7);
  EXPECT_EQ(drained.chunks, 2u);
  EXPECT_EQ(drained.steps, 8);
  EXPECT_EQ(drained.sequence_gaps, 1u) << "chunk 2 follows no stored chunk 1";
  EXPECT_DOUBLE_EQ(drained.lag_sum, 2 * (7.0 - 5.0));
  EXPECT_EQ(replay.size(), 8);
  EXPECT_EQ(queue.actors(), 1u);
  EXPECT_EQ(queue.drops().count(dds::DropReason::kDuplicate), 1u);
  EXPECT_EQ(queue.drops().count(dds::DropReason::kWrongRun), 1u);
  EXPECT_EQ(queue.drops().dropped(), 2u);

  const ChunkQueue::Drained nothing = queue.drain_into(replay, 7);
  EXPECT_EQ(nothing.chunks, 0u);
}

}  // namespace
}  // namespace indrive::learner
