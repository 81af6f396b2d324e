// Learning test of the task actor-critic on the dot environment: a world model with a reward
// head is trained on random-policy data, then the task actor-critic is trained purely in
// imagination on the reward head's predictions and must steer the dot into the goal corner.
#include <gtest/gtest.h>

#include <cstdio>

#include "dot_env.h"
#include "indrive/common/agent/behavior.h"
#include "indrive/common/agent/world_model.h"

namespace indrive::agent {
namespace {

// Mean predicted reward over an imagined rollout of `ac` from the posterior states of `batch`.
float imagined_reward(WorldModel& wm, ActorCritic& ac, const SequenceBatch& batch, nn::Rng& rng) {
  nn::current_graph().reset();
  nn::NoGradGuard no_grad;
  WorldModelOutput out = wm.observe(batch, false, rng);
  ImaginedTrajectory traj = ac.imagine(wm, {out.deter, out.stoch}, rng);
  nn::Tensor r = nn::twohot_mean(wm.reward_logits(traj.next_features()));
  double total = 0;
  for (float x : r.values()) total += x;
  return static_cast<float>(total / r.numel());
}

TEST(TaskActorCritic, LearnsToReachTheRewardedCornerInImagination) {
  // Thresholds: after 700 world-model updates (with reward head) and 150 actor-critic updates
  // in imagination, the mean imagined reward over 15 steps is above 0.4 and above twice that of
  // the untrained (near-uniform) actor from the same start states. A random walk spends about
  // 15% of its steps in the goal corner. Seeds fixed; about 40 s on one core.
  nn::set_threads(1);
  nn::Rng rng(21);
  const WorldModelConfig model = preset("tiny").world_model;
  WorldModel wm(model, rng);
  nn::Adam wm_opt(wm.params(), {.lr = 1e-3f, .eps = 1e-8f, .clip = 1000.0f});
  nn::Adam reward_opt(wm.reward_params(), {.lr = 1e-3f, .eps = 1e-8f, .clip = 1000.0f});
  ReplayBuffer replay(
      {.capacity = 5000, .height = 32, .width = 32, .has_rewards = true, .seed = 5});
  synthetic::DotEnv env(32, 7);
  synthetic::collect_random(env, replay, 3000, 9);
  for (int i = 0; i < 700; ++i) {
    nn::current_graph().reset();
    WorldModelOutput out = wm.observe(replay.sample(8, 8), true, rng);
    nn::current_graph().backward(out.loss);
    wm_opt.step();
    reward_opt.step();
  }

  BehaviorConfig behavior;
  behavior.units = 64;
  behavior.actor_lr = 1e-3f;
  behavior.critic_lr = 1e-3f;
  ActorCritic task("task", behavior, model.feat_dim(), rng);
  const SequenceBatch eval_batch = replay.sample(16, 4);
  nn::Rng eval_rng(1);
  const float before = imagined_reward(wm, task, eval_batch, eval_rng);
  for (int i = 0; i < 150; ++i) {
    nn::current_graph().reset();
    WorldModelOutput out;
    {
      nn::NoGradGuard frozen;
      out = wm.observe(replay.sample(8, 4), false, rng);
    }
    ImaginedTrajectory traj = task.imagine(wm, {out.deter, out.stoch}, rng);
    std::vector<float> rewards;
    {
      nn::NoGradGuard no_grad;
      nn::Tensor r = nn::twohot_mean(wm.reward_logits(traj.next_features()));
      rewards.assign(r.values().begin(), r.values().end());
    }
    nn::current_graph().backward(task.loss(traj, rewards));
    task.step();
  }
  nn::Rng eval_rng2(1);
  const float after = imagined_reward(wm, task, eval_batch, eval_rng2);
  std::printf("imagined reward per step: untrained actor %.3f, trained actor %.3f\n", before,
              after);
  EXPECT_GT(after, 0.4f);
  EXPECT_GT(after, 2.0f * before);
}

}  // namespace
}  // namespace indrive::agent
