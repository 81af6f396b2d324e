// Mixed precision does not change what is learned. The dot environment's world model is
// trained twice from the same seeds, with fp32 and with bf16 products, and the task
// actor-critic is trained in imagination with bf16 products; the thresholds are those of the
// fp32 learning tests (world_model_test.cc, behavior_learning_test.cc). Skipped where the CPU
// has no native bf16 (precision_fallback_test.cc covers that case).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <vector>

#include "dot_env.h"
#include "indrive/common/agent/behavior.h"
#include "indrive/common/agent/world_model.h"
#include "indrive/common/nn/kernels.h"

namespace indrive::agent {
namespace {

struct Curves {
  std::vector<float> recon, kl;  // means over windows of 50 updates
};

Curves train_dot_world_model(nn::Precision precision) {
  nn::set_threads(1);
  nn::set_precision(precision);
  nn::Rng rng(3);
  WorldModel wm(preset("tiny").world_model, rng);
  nn::Adam adam(wm.params(), {.lr = 1e-3f, .eps = 1e-8f, .clip = 1000.0f});
  ReplayBuffer replay(
      {.capacity = 10000, .height = 32, .width = 32, .has_rewards = false, .seed = 1});
  synthetic::DotEnv env(32, 5);
  synthetic::collect_random(env, replay, 3000, 9);
  const int updates = 700, window = 50;
  Curves c{std::vector<float>(updates / window), std::vector<float>(updates / window)};
  for (int i = 0; i < updates; ++i) {
    const SequenceBatch batch = replay.sample(8, 8);
    nn::current_graph().reset();
    WorldModelOutput out = wm.observe(batch, false, rng);
    nn::current_graph().backward(out.loss);
    adam.step();
    c.recon[i / window] += out.recon / window;
    c.kl[i / window] += out.kl / window;
  }
  nn::current_graph().reset();
  nn::set_precision(nn::Precision::kFp32);
  return c;
}

TEST(MixedPrecision, Bf16WorldModelLearnsTheDotEnvironmentAsFp32Does) {
  // Band, stated before measuring: every window's reconstruction error and KL of the bf16 run
  // within 25% (plus 0.5 nats or units, for values near zero) of the fp32 run's, and the fp32
  // test's own thresholds met by both. About 50 s on one core.
  if (!nn::bf16_supported()) GTEST_SKIP() << "no native bf16 here: " << nn::kernel_report();
  const Curves fp32 = train_dot_world_model(nn::Precision::kFp32);
  const Curves bf16 = train_dot_world_model(nn::Precision::kBf16);
  for (std::size_t w = 0; w < fp32.recon.size(); ++w) {
    std::printf("window %2zu  recon fp32 %8.2f bf16 %8.2f   kl fp32 %6.3f bf16 %6.3f\n", w,
                fp32.recon[w], bf16.recon[w], fp32.kl[w], bf16.kl[w]);
  }
  for (std::size_t w = 0; w < fp32.recon.size(); ++w) {
    EXPECT_NEAR(bf16.recon[w], fp32.recon[w], 0.25f * fp32.recon[w] + 0.5f) << "window " << w;
    EXPECT_NEAR(bf16.kl[w], fp32.kl[w], 0.25f * fp32.kl[w] + 0.5f) << "window " << w;
  }
  for (const Curves* c : {&fp32, &bf16}) {
    EXPECT_LT(c->recon.back(), 0.1f * c->recon.front());
    EXPECT_LT(c->kl.back(), 0.9f * *std::max_element(c->kl.begin(), c->kl.end()));
  }
}

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

TEST(MixedPrecision, Bf16TaskActorCriticReachesTheRewardedCorner) {
  // The thresholds of behavior_learning_test.cc (after 700 world-model and 150 actor-critic
  // updates the mean imagined reward is above 0.4 and above twice the untrained actor's), with
  // every product in bf16. About 40 s on one core.
  if (!nn::bf16_supported()) GTEST_SKIP() << "no native bf16 here: " << nn::kernel_report();
  nn::set_threads(1);
  nn::set_precision(nn::Precision::kBf16);
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
  nn::current_graph().reset();
  nn::set_precision(nn::Precision::kFp32);
  std::printf("bf16: imagined reward per step: untrained actor %.3f, trained actor %.3f\n", before,
              after);
  EXPECT_GT(after, 0.4f);
  EXPECT_GT(after, 2.0f * before);
}

}  // namespace
}  // namespace indrive::agent
