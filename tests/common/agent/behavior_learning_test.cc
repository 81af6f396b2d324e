// Learning test of the task actor-critic on the dot environment: a world model with a reward
// head is trained on random-policy data, then the task actor-critic is trained purely in
// imagination on the reward head's predictions and must steer the dot into the goal corner.
#include <gtest/gtest.h>

#include <cstdio>

#include "dot_learning.h"

namespace indrive::agent {
namespace {

TEST(TaskActorCritic, LearnsToReachTheRewardedCornerInImagination) {
  // Thresholds: after 700 world-model updates (with reward head) and 150 actor-critic updates
  // in imagination, the mean imagined reward over 15 steps is above 0.4 and above twice that of
  // the untrained (near-uniform) actor from the same start states. A random walk spends about
  // 15% of its steps in the goal corner. Seeds fixed; about 40 s on one core. fp32 products
  // (the engine's default); precision_test.cc runs the same with bf16.
  nn::set_threads(1);
  const dot_learning::CornerRewards r = dot_learning::train_task_actor_to_the_corner();
  std::printf("imagined reward per step: untrained actor %.3f, trained actor %.3f\n", r.before,
              r.after);
  EXPECT_GT(r.after, 0.4f);
  EXPECT_GT(r.after, 2.0f * r.before);
}

}  // namespace
}  // namespace indrive::agent
