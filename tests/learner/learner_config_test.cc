// Tests of learner_config.h: the learner's typed view of the run configuration.
#include "indrive/learner/learner_config.h"

#include <gtest/gtest.h>

#include "indrive/service/run_config.h"
#include "testing.h"

namespace indrive::learner {
namespace {

LearnerConfig resolved(const std::vector<std::string>& overrides) {
  testing::TempDir dir;
  const auto service =
      service::ServiceConfig::resolve({.run_dir = dir.path() / "r", .overrides = overrides});
  return learner_config(service.config());
}

TEST(LearnerConfigTest, TheStructsDefaultsAreTheDeclaredOnes) {
  EXPECT_EQ(resolved({}), LearnerConfig{})
      << "a default changed in run_config.cc and not here, or the other way round";
}

TEST(LearnerConfigTest, EveryKeyReachesItsField) {
  const LearnerConfig c = resolved(
      {"run.seed=7", "run.budget_env_steps=900", "learner.replay_ratio=16", "learner.async=true",
       "learner.snapshot_every=3", "learner.announce_s=0.5", "learner.snapshot_hold_s=2",
       "learner.log_interval_s=1.5", "learner.log_every_env_steps=0",
       "learner.checkpoint_minutes=0.5", "learner.checkpoint_keep=5",
       "learner.init_checkpoint=runs/p/checkpoints/ckpt-1.bin", "learner.dashboard_s=0"});
  EXPECT_EQ(c.seed, 7);
  EXPECT_EQ(c.budget_env_steps, 900);
  EXPECT_DOUBLE_EQ(c.replay_ratio, 16.0);
  EXPECT_TRUE(c.async);
  EXPECT_EQ(c.snapshot_every, 3);
  EXPECT_DOUBLE_EQ(c.announce_s, 0.5);
  EXPECT_DOUBLE_EQ(c.snapshot_hold_s, 2.0);
  EXPECT_DOUBLE_EQ(c.log_interval_s, 1.5);
  EXPECT_EQ(c.log_every_env_steps, 0);
  EXPECT_DOUBLE_EQ(c.checkpoint_s, 30.0) << "minutes in the file, seconds in the struct";
  EXPECT_EQ(c.checkpoint_keep, 5);
  EXPECT_EQ(c.init_checkpoint, "runs/p/checkpoints/ckpt-1.bin");
  EXPECT_DOUBLE_EQ(c.dashboard_s, 0.0);
}

// An actor must always be able to finish the chunk it holds: the slack is at least one chunk.
TEST(LearnerConfigTest, TheAllowanceSlackIsAtLeastOneChunk) {
  EXPECT_EQ(resolved({"learner.allowance_slack=8", "actor.chunk_length=32"}).allowance_slack, 32);
  EXPECT_EQ(resolved({"learner.allowance_slack=100", "actor.chunk_length=32"}).allowance_slack,
            100);
}

}  // namespace
}  // namespace indrive::learner
