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

}  // namespace
}  // namespace indrive::learner
