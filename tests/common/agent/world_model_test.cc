#include "indrive/common/agent/world_model.h"

#include <gtest/gtest.h>

#include <cmath>

#include "dot_env.h"

namespace indrive::agent {
namespace {

WorldModelConfig tiny_model() {
  WorldModelConfig c = preset("tiny").world_model;
  return c;
}

ReplayBuffer dot_replay(int steps, bool rewards = false) {
  ReplayBuffer replay(
      {.capacity = 10000, .height = 32, .width = 32, .has_rewards = rewards, .seed = 1});
  synthetic::DotEnv env(32, 5);
  synthetic::collect_random(env, replay, steps, 9);
  return replay;
}

TEST(WorldModel, ShapesAndFiniteLoss) {
  nn::Rng rng(1);
  WorldModel wm(tiny_model(), rng);
  ReplayBuffer replay = dot_replay(100);
  const SequenceBatch batch = replay.sample(3, 5);
  nn::current_graph().reset();
  WorldModelOutput out = wm.observe(batch, false, rng);
  EXPECT_EQ(out.features.dim(0), 15);
  EXPECT_EQ(out.features.dim(1), 128 + 256);
  EXPECT_EQ(out.post_probs.dim(1), 256);
  EXPECT_TRUE(std::isfinite(out.loss.item()));
  // Free bits: each KL term is at least 1 nat.
  EXPECT_GE(out.dyn, 1.0f);
  EXPECT_GE(out.rep, 1.0f);
  // Sampled latents are one-hot per group.
  const float* s = out.stoch.data();
  for (int g = 0; g < 16; ++g) {
    float total = 0;
    for (int c = 0; c < 16; ++c) total += s[g * 16 + c];
    EXPECT_FLOAT_EQ(total, 1.0f);
  }
  // Posterior probabilities carry the 1% uniform mix: no class below 0.01 / 16.
  for (float p : out.post_probs.values()) EXPECT_GE(p, 0.01f / 16 - 1e-7f);
}

TEST(WorldModel, RewardHeadTrainsOnStopGradientFeatures) {
  nn::Rng rng(2);
  WorldModel wm(tiny_model(), rng);
  ReplayBuffer replay = dot_replay(200, true);
  const SequenceBatch batch = replay.sample(2, 6);
  // Loss with and without the reward term: the world model's gradient must be identical,
  // because the reward head sees stop-gradient features.
  auto grads = [&](bool with_reward) {
    nn::Rng sample_rng(7);
    wm.params().zero_grad();
    wm.reward_params().zero_grad();
    nn::current_graph().reset();
    WorldModelOutput out = wm.observe(batch, with_reward, sample_rng);
    nn::current_graph().backward(out.loss);
    std::vector<float> g;
    for (const auto& p : wm.params().params())
      g.insert(g.end(), p->grad().begin(), p->grad().end());
    return g;
  };
  const std::vector<float> without = grads(false);
  const std::vector<float> with = grads(true);
  EXPECT_EQ(without, with);
  // The reward head itself does get a gradient (from its output layer at least).
  float reward_grad = 0;
  for (const auto& p : wm.reward_params().params())
    for (float g : p->grad()) reward_grad += std::abs(g);
  EXPECT_GT(reward_grad, 0.0f);
}

TEST(WorldModel, LearnsTheDotEnvironment) {
  // Thresholds: reconstruction error (summed over 32x32x3) falls by more than half within
  // 150 updates, and the KL falls; seeds fixed.
  nn::set_threads(1);
  nn::Rng rng(3);
  WorldModelConfig config = tiny_model();
  WorldModel wm(config, rng);
  nn::Adam adam(wm.params(), {.lr = 1e-3f, .eps = 1e-8f, .clip = 1000.0f});
  ReplayBuffer replay = dot_replay(2000);
  float first_recon = 0, last_recon = 0, first_kl = 0, last_kl = 0;
  const int updates = 150;
  for (int i = 0; i < updates; ++i) {
    const SequenceBatch batch = replay.sample(8, 8);
    nn::current_graph().reset();
    WorldModelOutput out = wm.observe(batch, false, rng);
    nn::current_graph().backward(out.loss);
    adam.step();
    if (i < 10) first_recon += out.recon / 10, first_kl += out.kl / 10;
    if (i >= updates - 10) last_recon += out.recon / 10, last_kl += out.kl / 10;
  }
  RecordProperty("first_recon", std::to_string(first_recon));
  RecordProperty("last_recon", std::to_string(last_recon));
  std::printf("recon %.2f -> %.2f, kl %.2f -> %.2f\n", first_recon, last_recon, first_kl, last_kl);
  EXPECT_LT(last_recon, 0.5f * first_recon);
  EXPECT_LT(last_kl, first_kl);
}

}  // namespace
}  // namespace indrive::agent
