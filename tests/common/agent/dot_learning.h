// The learning procedures on the dot environment that the fp32 learning tests
// (world_model_test.cc, behavior_learning_test.cc) and the mixed-precision test
// (precision_test.cc) share: each runs at whatever product precision is set (nn/kernels.h).
#pragma once

#include <vector>

#include "dot_env.h"
#include "indrive/agent/behavior.h"
#include "indrive/agent/world_model.h"

namespace indrive::agent::dot_learning {

// The tiny world model trained for `updates` updates on 3,000 random-policy steps (seeds
// fixed), with its reconstruction error and KL averaged over windows of 50 updates.
class TrainedWorldModel {
 public:
  static constexpr int kWindow = 50;
  explicit TrainedWorldModel(int updates = 700)
      : wm(preset("tiny").world_model, rng),
        adam(wm.params(), {.lr = 1e-3f, .eps = 1e-8f, .clip = 1000.0f}),
        replay({.capacity = 10000, .height = 32, .width = 32, .has_rewards = false, .seed = 1}),
        recon(updates / kWindow, 0.0f),
        kl(updates / kWindow, 0.0f) {
    synthetic::DotEnv env(32, 5);
    synthetic::collect_random(env, replay, 3000, 9);
    for (int i = 0; i < updates; ++i) {
      const SequenceBatch batch = replay.sample(8, 8);
      nn::current_graph().reset();
      WorldModelOutput out = wm.observe(batch, false, rng);
      nn::current_graph().backward(out.loss);
      adam.step();
      recon[i / kWindow] += out.recon / kWindow;
      kl[i / kWindow] += out.kl / kWindow;
    }
  }

  nn::Rng rng{3};
  WorldModel wm;
  nn::Adam adam;
  ReplayBuffer replay;
  std::vector<float> recon, kl;
};

// Mean predicted reward over an imagined rollout of `ac` from the posterior states of `batch`.
inline float imagined_reward(WorldModel& wm, ActorCritic& ac, const SequenceBatch& batch,
                             nn::Rng& rng) {
  nn::current_graph().reset();
  nn::NoGradGuard no_grad;
  WorldModelOutput out = wm.observe(batch, false, rng);
  ImaginedTrajectory traj = ac.imagine(wm, {out.deter, out.stoch}, rng);
  nn::Tensor r = nn::twohot_mean(wm.reward_logits(traj.next_features()));
  double total = 0;
  for (float x : r.values()) total += x;
  return static_cast<float>(total / r.numel());
}

struct CornerRewards {
  float before, after;  // mean imagined reward per step of the untrained and trained actor
};

// A world model with a reward head trained for 700 updates on random-policy data, then the
// task actor-critic trained for 150 updates purely in imagination on the reward head's
// predictions, to steer the dot into the goal corner (seeds fixed).
inline CornerRewards train_task_actor_to_the_corner() {
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
  CornerRewards result;
  result.before = imagined_reward(wm, task, eval_batch, eval_rng);
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
  result.after = imagined_reward(wm, task, eval_batch, eval_rng2);
  nn::current_graph().reset();
  return result;
}

}  // namespace indrive::agent::dot_learning
