// Tests of ops_dist.cc: categorical latents (unimix, straight-through samples, KL, entropy),
// two-hot values and the losses.
#include "ops_test_support.h"

namespace indrive::nn {
namespace {

TEST_F(OpsTest, CategoricalOps) {
  Parameter& logits = input("logits", {3, 2 * 4}, -2.0f, 2.0f);
  Parameter& other = input("other", {3, 2 * 4}, -2.0f, 2.0f);
  EXPECT_EQ(check("unimix", [&] { return unimix_probs(logits.tensor(), 4); }), 0);
  EXPECT_EQ(check("kl",
                  [&] {
                    return kl_categorical(unimix_probs(logits.tensor(), 4),
                                          unimix_probs(other.tensor(), 4));
                  }),
            0);
  EXPECT_EQ(check("entropy",
                  [&] {
                    return entropy(softmax(reshape(logits.tensor(), Shape{6, 4})));
                  }),
            0);
  Tensor p = unimix_probs(logits.tensor(), 4);
  for (std::int64_t i = 0; i < p.numel(); ++i) EXPECT_GE(p.data()[i], 0.01f / 4 - 1e-7f);
  EXPECT_NEAR(kl_categorical(p, p).data()[0], 0.0f, 1e-6f);
  // KL against the uniform distribution is log(classes) - entropy, per group, summed.
  Tensor u = full(p.shape(), 0.25f);
  Tensor kl = kl_categorical(p, u);
  Tensor h = entropy(reshape(p, Shape{6, 4}));
  EXPECT_NEAR(kl.data()[1], 2 * std::log(4.0f) - h.data()[2] - h.data()[3], 1e-5f);
}

TEST_F(OpsTest, StraightThroughSampleIsOneHotWithIdentityGradient) {
  Parameter& logits = input("logits", {2, 3 * 5}, -2.0f, 2.0f);
  Rng rng(5);
  Tensor probs = unimix_probs(logits.tensor(), 5);
  Tensor sample = sample_straight_through(probs, 5, rng);
  for (int g = 0; g < 6; ++g) {
    float total = 0;
    for (int c = 0; c < 5; ++c) {
      const float v = sample.data()[g * 5 + c];
      EXPECT_TRUE(v == 0.0f || v == 1.0f);
      total += v;
    }
    EXPECT_EQ(total, 1.0f);
  }
  // The gradient through the sample equals the gradient through probs.
  Tensor weights = constant(sample.shape(), std::vector<float>(30, 0.0f));
  for (int i = 0; i < 30; ++i) weights.data()[i] = static_cast<float>(i % 7) - 3.0f;
  current_graph().backward(sum(mul(sample, weights)));
  std::vector<float> via_sample(logits.grad().begin(), logits.grad().end());
  in_.zero_grad();
  current_graph().reset();
  Tensor probs2 = unimix_probs(logits.tensor(), 5);
  Tensor weights2 = constant(probs2.shape(), std::vector<float>(30, 0.0f));
  for (int i = 0; i < 30; ++i) weights2.data()[i] = static_cast<float>(i % 7) - 3.0f;
  current_graph().backward(sum(mul(probs2, weights2)));
  for (int i = 0; i < 30; ++i) EXPECT_FLOAT_EQ(via_sample[i], logits.grad()[i]);
}

TEST_F(OpsTest, SamplingFollowsTheProbabilities) {
  // 20000 draws from (0.1, 0.6, 0.3): frequencies within 4 standard errors.
  std::vector<float> probs;
  for (int i = 0; i < 20000; ++i) probs.insert(probs.end(), {0.1f, 0.6f, 0.3f});
  Rng rng(3);
  Tensor s = sample_straight_through(constant({20000, 3}, probs), 3, rng);
  double counts[3] = {0, 0, 0};
  for (int i = 0; i < 20000; ++i)
    for (int c = 0; c < 3; ++c) counts[c] += s.data()[i * 3 + c];
  const double expect[3] = {0.1, 0.6, 0.3};
  for (int c = 0; c < 3; ++c) {
    const double se = std::sqrt(expect[c] * (1 - expect[c]) / 20000);
    EXPECT_NEAR(counts[c] / 20000, expect[c], 4 * se);
  }
}

TEST_F(OpsTest, TwoHotEncodingAndLoss) {
  // The encoding puts its mass on the two bins around symlog(t), with the right mean.
  Tensor t = constant({4}, std::vector<float>{0.0f, 3.7f, -150.0f, 1e12f});
  Tensor enc = twohot(t);
  ASSERT_EQ(enc.shape(), (Shape{4, kTwoHotBins}));
  const float step = (kTwoHotHigh - kTwoHotLow) / (kTwoHotBins - 1);
  for (int r = 0; r < 3; ++r) {
    double total = 0, mean_bin = 0;
    int nonzero = 0;
    for (int k = 0; k < kTwoHotBins; ++k) {
      const float v = enc.data()[r * kTwoHotBins + k];
      total += v;
      mean_bin += v * (kTwoHotLow + k * step);
      nonzero += v != 0.0f;
    }
    EXPECT_NEAR(total, 1.0, 1e-6);
    EXPECT_LE(nonzero, 2);
    const float v = t.data()[r];
    EXPECT_NEAR(mean_bin, std::copysign(std::log1p(std::fabs(v)), v), 1e-5);
  }
  EXPECT_EQ(enc.data()[3 * kTwoHotBins + kTwoHotBins - 1], 1.0f);  // clipped to the last bin

  Parameter& logits = input("logits", {3, kTwoHotBins}, -1.0f, 1.0f);
  const std::vector<float> targets = {0.5f, -8.0f, 40.0f};
  // Constants are made inside the lambdas: the check resets the graph between evaluations.
  EXPECT_EQ(check("twohot ce",
                  [&] { return twohot_cross_entropy(logits.tensor(), constant({3}, targets)); }),
            0);
  EXPECT_EQ(check("twohot mean", [&] { return twohot_mean(logits.tensor()); },
                  {.step = 1e-2f, .atol = 5e-3f, .rtol = 3e-2f}),
            0);
  // Logits that put all mass on the encoding decode back to the target.
  Tensor target = constant({3}, targets);
  Tensor exact = log(add_scalar(twohot(target), 1e-30f));
  Tensor decoded = twohot_mean(exact);
  for (int r = 0; r < 3; ++r)
    EXPECT_NEAR(decoded.data()[r], target.data()[r], 1e-3f * std::fabs(target.data()[r]));
}

TEST_F(OpsTest, LossGradientsAndValues) {
  Parameter& x = input("x", {4, 3}, -3.0f, 3.0f);
  std::vector<float> targets(12);
  for (int i = 0; i < 12; ++i) targets[i] = static_cast<float>(i % 2);
  EXPECT_EQ(check("bce",
                  [&] {
                    return bce_with_logits(x.tensor(), constant({4, 3}, targets));
                  }),
            0);
  EXPECT_EQ(check("squared_error",
                  [&] {
                    return squared_error(x.tensor(), constant({4, 3}, targets));
                  }),
            0);
  EXPECT_EQ(check("mse", [&] { return mse(x.tensor(), constant({4, 3}, targets)); }), 0);
  Tensor t = constant({4, 3}, targets);
  Tensor bce = bce_with_logits(x.tensor(), t);
  for (int i = 0; i < 12; ++i) {
    const double s = 1.0 / (1.0 + std::exp(-x.value()[i]));
    const double expect = -(targets[i] * std::log(s) + (1 - targets[i]) * std::log(1 - s));
    EXPECT_NEAR(bce.data()[i], expect, 1e-5);
  }
}

}  // namespace
}  // namespace indrive::nn
