#include "indrive/agent/world_model.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "dot_env.h"
#include "dot_learning.h"

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

// A (B, T) field is batch-major (step t of sequence b at b * T + t); the model's rows are
// time-major (t * B + b). Written out for B = 3, T = 4, and the column built from it.
TEST(WorldModel, TimeMajorRowsOfABatchMajorField) {
  EXPECT_EQ(WorldModel::time_major_row(0, 3, 4), 0u);    // b 0, t 0
  EXPECT_EQ(WorldModel::time_major_row(1, 3, 4), 3u);    // b 0, t 1
  EXPECT_EQ(WorldModel::time_major_row(3, 3, 4), 9u);    // b 0, t 3
  EXPECT_EQ(WorldModel::time_major_row(4, 3, 4), 1u);    // b 1, t 0
  EXPECT_EQ(WorldModel::time_major_row(6, 3, 4), 7u);    // b 1, t 2
  EXPECT_EQ(WorldModel::time_major_row(11, 3, 4), 11u);  // b 2, t 3
  std::vector<float> field(12);
  for (int b = 0; b < 3; ++b) {
    for (int t = 0; t < 4; ++t) field[b * 4 + t] = 10.0f * b + t;
  }
  const nn::Tensor column = WorldModel::time_major_column(field, 3, 4);
  ASSERT_EQ(column.numel(), 12);
  for (int t = 0; t < 4; ++t) {
    for (int b = 0; b < 3; ++b) EXPECT_EQ(column.data()[t * 3 + b], 10.0f * b + t);
  }
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

TEST(WorldModel, LearnsTheDotEnvironmentAndImaginesItOpenLoop) {
  // Thresholds: the reconstruction error (summed over 32x32x3) falls below a tenth within
  // 700 updates and the KL ends 10% below its peak; then, from 4 observed steps, 4 open-loop
  // imagined frames (true actions, prior only) have less than 0.6 times the error of repeating the
  // last observed frame. Seeds fixed; about 25 s on one core.
  nn::set_threads(1);
  dot_learning::TrainedWorldModel trained;
  const std::vector<float>& recon = trained.recon;
  const std::vector<float>& kl = trained.kl;
  WorldModel& wm = trained.wm;
  ReplayBuffer& replay = trained.replay;
  nn::Rng& rng = trained.rng;
  const float peak_kl = *std::max_element(kl.begin(), kl.end());
  std::printf("recon %.2f -> %.2f, kl %.2f, peak %.2f -> %.2f\n", recon.front(), recon.back(),
              kl.front(), peak_kl, kl.back());
  EXPECT_LT(recon.back(), 0.1f * recon.front());
  EXPECT_LT(kl.back(), 0.9f * peak_kl);

  // Open loop: observe steps 0..3 of 16 windows, then roll the prior with the true actions.
  nn::NoGradGuard no_grad;
  nn::current_graph().reset();
  const int b = 16, context = 4, horizon = 4;
  SequenceBatch batch = replay.sample(b, context + horizon);
  for (int i = 0; i < b; ++i) {
    // Windows that cross an episode start would reset mid-way: treat them as one episode.
    for (int t = 1; t < context + horizon; ++t) batch.is_first[i * (context + horizon) + t] = 0;
  }
  SequenceBatch observed = batch;
  observed.length = context;
  observed.frames.clear(), observed.actions.clear(), observed.is_first.clear();
  observed.is_last.clear(), observed.is_terminal.clear();
  const std::size_t pixels = 32 * 32;
  for (int i = 0; i < b; ++i) {
    for (int t = 0; t < context; ++t) {
      const std::size_t k = i * (context + horizon) + t;
      observed.frames.insert(observed.frames.end(), batch.frames.begin() + k * pixels,
                             batch.frames.begin() + (k + 1) * pixels);
      observed.actions.push_back(batch.actions[k]);
      observed.is_first.push_back(batch.is_first[k]);
      observed.is_last.push_back(0);
      observed.is_terminal.push_back(0);
    }
  }
  WorldModelOutput out = wm.observe(observed, false, rng);
  RssmState state{nn::slice(out.deter, (context - 1) * b, context * b, 0),
                  nn::slice(out.stoch, (context - 1) * b, context * b, 0)};
  nn::Tensor real = WorldModel::batch_images(batch);  // ((context + horizon) * b, 32, 32, 3)
  const std::int64_t frame_size = 32 * 32 * 3;
  double model_error = 0, copy_error = 0;
  for (int t = context; t < context + horizon; ++t) {
    std::vector<int> actions(b);
    for (int i = 0; i < b; ++i) actions[i] = batch.actions[i * (context + horizon) + t - 1];
    state = wm.img_step(state, WorldModel::one_hot(actions), rng);
    nn::Tensor imagined = wm.decode(WorldModel::features(state));
    for (int i = 0; i < b; ++i) {
      const float* truth = real.data() + (t * b + i) * frame_size;
      const float* last_seen = real.data() + ((context - 1) * b + i) * frame_size;
      const float* pred = imagined.data() + i * frame_size;
      for (std::int64_t k = 0; k < frame_size; ++k) {
        model_error += (pred[k] - truth[k]) * (pred[k] - truth[k]);
        copy_error += (last_seen[k] - truth[k]) * (last_seen[k] - truth[k]);
      }
    }
  }
  model_error /= b * horizon, copy_error /= b * horizon;
  std::printf("open-loop error per frame %.2f, copy-last-frame error %.2f\n", model_error,
              copy_error);
  EXPECT_LT(model_error, 0.6 * copy_error);
}

}  // namespace
}  // namespace indrive::agent
