#include "indrive/learner/learner.h"

#include <gtest/gtest.h>

namespace indrive::learner {
namespace {

TEST(LearnerCheckpointTest, PackedCountersAndAgentBytesRoundTrip) {
  const LearnerCounters counters{
      .env_steps = 12345, .updates = 678, .policy_version = 9, .learner_epoch = 2};
  const std::vector<std::uint8_t> agent_bytes = {0, 1, 2, '\n', 255, 7};
  const auto packed = pack_checkpoint(counters, agent_bytes);
  std::vector<std::uint8_t> restored_bytes;
  const LearnerCounters restored = unpack_checkpoint(packed, restored_bytes);
  EXPECT_EQ(restored.env_steps, 12345);
  EXPECT_EQ(restored.updates, 678);
  EXPECT_EQ(restored.policy_version, 9u);
  EXPECT_EQ(restored.learner_epoch, 2u);
  EXPECT_EQ(restored_bytes, agent_bytes);
}

TEST(LearnerCheckpointTest, ForeignOrTruncatedFilesThrow) {
  std::vector<std::uint8_t> bytes;
  const std::string other = "not a checkpoint";
  EXPECT_THROW(unpack_checkpoint(std::vector<std::uint8_t>(other.begin(), other.end()), bytes),
               CheckpointError);
  auto packed = pack_checkpoint({}, std::vector<std::uint8_t>{1, 2});
  packed.resize(35);  // inside the counters line
  EXPECT_THROW(unpack_checkpoint(packed, bytes), CheckpointError);
}

TEST(LearnerCheckpointTest, ReplaySectionRoundTripsCompressed) {
  // A replay file of class-id frames: long runs of few values, as the camera makes them.
  std::vector<std::uint8_t> replay_bytes(200000);
  for (std::size_t i = 0; i < replay_bytes.size(); ++i) replay_bytes[i] = (i / 700) % 8;
  const std::vector<std::uint8_t> agent_bytes = {9, 8, 7};
  const auto packed = pack_checkpoint({.env_steps = 5, .updates = 1}, agent_bytes, replay_bytes);
  EXPECT_LT(packed.size(), replay_bytes.size() / 10) << "zstd shrinks class-id frames";
  std::vector<std::uint8_t> agent_out, replay_out = {1};
  EXPECT_EQ(unpack_checkpoint(packed, agent_out, &replay_out).env_steps, 5);
  EXPECT_EQ(agent_out, agent_bytes);
  EXPECT_EQ(replay_out, replay_bytes);

  // Without a replay section the replay comes back empty.
  const auto bare = pack_checkpoint({}, agent_bytes);
  unpack_checkpoint(bare, agent_out, &replay_out);
  EXPECT_TRUE(replay_out.empty());
  EXPECT_EQ(agent_out, agent_bytes);
}

TEST(LearnerCheckpointTest, TruncatedOrDamagedReplaySectionThrows) {
  std::vector<std::uint8_t> replay_bytes(5000, 3);
  const auto packed = pack_checkpoint({}, std::vector<std::uint8_t>{1, 2, 3}, replay_bytes);
  std::vector<std::uint8_t> agent_out, replay_out;
  auto truncated = packed;
  truncated.pop_back();
  EXPECT_THROW(unpack_checkpoint(truncated, agent_out, &replay_out), CheckpointError);
  auto damaged = packed;
  damaged[damaged.size() - 4] ^= 0xFF;  // inside the zstd frame
  EXPECT_THROW(unpack_checkpoint(damaged, agent_out, &replay_out), CheckpointError);
}

TEST(LearnerCheckpointTest, ReadsTheFormatWithoutReplay) {
  const std::string v1 =
      "INDRIVE-LEARNER-CHECKPOINT 1\n"
      R"({"env_steps":10,"updates":2,"policy_version":3,"learner_epoch":1})"
      "\nAGENT";
  std::vector<std::uint8_t> agent_out, replay_out = {1};
  const auto counters =
      unpack_checkpoint(std::vector<std::uint8_t>(v1.begin(), v1.end()), agent_out, &replay_out);
  EXPECT_EQ(counters.policy_version, 3u);
  EXPECT_EQ(std::string(agent_out.begin(), agent_out.end()), "AGENT");
  EXPECT_TRUE(replay_out.empty());
}

}  // namespace
}  // namespace indrive::learner
