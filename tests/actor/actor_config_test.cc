// Tests of actor_config.h: the actor folder's typed views of the actor.* and eval.* keys.
#include "indrive/actor/actor_config.h"

#include <gtest/gtest.h>

#include "indrive/service/run_config.h"
#include "testing.h"

namespace indrive::actor {
namespace {

service::ServiceConfig resolved(const std::vector<std::string>& overrides) {
  testing::TempDir dir;
  return service::ServiceConfig::resolve({.run_dir = dir.path() / "r", .overrides = overrides});
}

TEST(ActorConfigTest, TheStructsDefaultsAreTheDeclaredOnes) {
  const auto defaults = resolved({});
  EXPECT_EQ(actor_config(defaults.config()), ActorConfig{})
      << "a default changed in run_config.cc and not in actor_config.h, or the other way round";
  EXPECT_EQ(eval_config(defaults.config()), EvalConfig{})
      << "a default changed in run_config.cc and not in actor_config.h, or the other way round";
}

TEST(ActorConfigTest, EveryActorKeyReachesItsField) {
  const ActorConfig a = actor_config(
      resolved({"actor.chunk_length=32", "actor.heartbeat_s=0.5", "actor.request_after_s=3",
                "actor.rejoin_after_s=7", "actor.rejoin_max_s=70", "actor.coverage_period_s=9"})
          .config());
  EXPECT_EQ(a.chunk_length, 32);
  EXPECT_DOUBLE_EQ(a.heartbeat_s, 0.5);
  EXPECT_DOUBLE_EQ(a.request_after_s, 3.0);
  EXPECT_DOUBLE_EQ(a.rejoin_after_s, 7.0);
  EXPECT_DOUBLE_EQ(a.rejoin_max_s, 70.0);
  EXPECT_DOUBLE_EQ(a.coverage_period_s, 9.0);
}

TEST(ActorConfigTest, EveryEvalKeyReachesItsField) {
  const EvalConfig e = eval_config(resolved({"eval.towns=town02",
                                             "eval.routes=straight",
                                             "eval.densities=[0,5]",
                                             "eval.episodes_per_cell=3",
                                             "eval.policy=oracle",
                                             "eval.snapshot_file=s.params",
                                             "eval.head=task",
                                             "eval.kind=few_shot",
                                             "eval.oracle_brake=false",
                                             "eval.oracle_speed_mps=4",
                                             "eval.wait_for_done=false",
                                             "eval.snapshot_timeout_s=60",
                                             "eval.learner_silence_s=0",
                                             "eval.continuous=true",
                                             "eval.every_k=2",
                                             "eval.resume=true",
                                             "eval.protocol=indrive_code",
                                             "eval.indrive_code_budget_steps=3000",
                                             "eval.budget_speed_mps=2",
                                             "eval.budget_slack=2",
                                             "eval.video_episodes=1",
                                             "eval.probe_far_m=20",
                                             "eval.probe_near_m=4",
                                             "eval.probe_oracle_brake=true"})
                                       .config());
  EXPECT_EQ(e.towns, "town02");
  EXPECT_EQ(e.routes, "straight");
  EXPECT_EQ(e.densities, (std::vector<double>{0, 5}));
  EXPECT_EQ(e.episodes_per_cell, 3);
  EXPECT_EQ(e.policy, "oracle");
  EXPECT_EQ(e.snapshot_file, "s.params");
  EXPECT_EQ(e.head, "task");
  EXPECT_EQ(e.kind, "few_shot");
  EXPECT_FALSE(e.oracle_brake);
  EXPECT_DOUBLE_EQ(e.oracle_speed_mps, 4.0);
  EXPECT_FALSE(e.wait_for_done);
  EXPECT_DOUBLE_EQ(e.snapshot_timeout_s, 60.0);
  EXPECT_DOUBLE_EQ(e.learner_silence_s, 0.0);
  EXPECT_TRUE(e.continuous);
  EXPECT_EQ(e.every_k, 2);
  EXPECT_TRUE(e.resume);
  EXPECT_EQ(e.protocol, "indrive_code");
  EXPECT_EQ(e.indrive_code_budget_steps, 3000);
  EXPECT_DOUBLE_EQ(e.budget_speed_mps, 2.0);
  EXPECT_DOUBLE_EQ(e.budget_slack, 2.0);
  EXPECT_EQ(e.video_episodes, 1);
  EXPECT_DOUBLE_EQ(e.probe_far_m, 20.0);
  EXPECT_DOUBLE_EQ(e.probe_near_m, 4.0);
  EXPECT_TRUE(e.probe_oracle_brake);
}

}  // namespace
}  // namespace indrive::actor
