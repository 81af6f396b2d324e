#include "indrive/agent/returns.h"

#include <gtest/gtest.h>

#include <cmath>
#include <numeric>
#include <vector>

namespace indrive::agent {
namespace {

TEST(LambdaReturns, MatchesHandComputedRecursion) {
  // H = 2, N = 1, gamma 0.9, lambda 0.5.
  // R_2 = 30; R_1 = 2 + 0.9 * 0.5 * (0.5 * 30 + 0.5 * 30) = 15.5;
  // R_0 = 1 + 0.9 * 1 * (0.5 * 20 + 0.5 * 15.5) = 16.975.
  const std::vector<float> r = {1, 2}, c = {1, 0.5f}, v = {10, 20, 30};
  const std::vector<float> ret = lambda_returns(r, c, v, 2, 1, 0.9f, 0.5f);
  ASSERT_EQ(ret.size(), 2u);
  EXPECT_NEAR(ret[0], 16.975f, 1e-5);
  EXPECT_NEAR(ret[1], 15.5f, 1e-5);
}

TEST(LambdaReturns, LambdaOneIsMonteCarloAndZeroIsOneStep) {
  const std::vector<float> r = {1, 2}, c = {1, 0.5f}, v = {10, 20, 30};
  // lambda = 1: 1 + 0.9 * (2 + 0.9 * 0.5 * 30) = 14.95.
  EXPECT_NEAR(lambda_returns(r, c, v, 2, 1, 0.9f, 1.0f)[0], 14.95f, 1e-5);
  // lambda = 0: 1 + 0.9 * 20 = 19.
  EXPECT_NEAR(lambda_returns(r, c, v, 2, 1, 0.9f, 0.0f)[0], 19.0f, 1e-5);
}

TEST(LambdaReturns, ColumnsAreIndependentAndTerminalStopsBootstrap) {
  // Two trajectories in one call, (H, N) = (1, 2); the second ends (continue 0).
  const std::vector<float> r = {1, 1}, c = {1, 0}, v = {0, 0, 5, 5};
  const std::vector<float> ret = lambda_returns(r, c, v, 1, 2, 0.99f, 0.95f);
  EXPECT_NEAR(ret[0], 1 + 0.99f * 5, 1e-5);
  EXPECT_NEAR(ret[1], 1.0f, 1e-6);
}

TEST(Quantile, LinearInterpolationLikeNumpy) {
  const std::vector<float> x = {4, 1, 3, 2};
  EXPECT_NEAR(quantile(x, 0.05f), 1.15f, 1e-5);  // position 0.15
  EXPECT_NEAR(quantile(x, 0.95f), 3.85f, 1e-5);  // position 2.85
  EXPECT_FLOAT_EQ(quantile(x, 0.0f), 1.0f);
  EXPECT_FLOAT_EQ(quantile(x, 1.0f), 4.0f);
}

TEST(ReturnNormalizer, EmaOfPercentilesWithFloor) {
  std::vector<float> x(101);
  std::iota(x.begin(), x.end(), 0.0f);  // 5th percentile 5, 95th 95
  ReturnNormalizer norm(0.05f, 0.95f, 0.99f, 1.0f);
  norm.update(x);
  EXPECT_NEAR(norm.low(), 0.05f, 1e-6);
  EXPECT_NEAR(norm.high(), 0.95f, 1e-6);
  EXPECT_FLOAT_EQ(norm.scale(), 1.0f);  // range 0.9 is below the floor
  norm.update(x);
  // After k updates from 0: p * (1 - 0.99^k).
  EXPECT_NEAR(norm.low(), 5 * (1 - 0.9801f), 1e-5);
  EXPECT_NEAR(norm.high(), 95 * (1 - 0.9801f), 1e-5);
  EXPECT_NEAR(norm.scale(), 90 * (1 - 0.9801f), 1e-5);
  for (int i = 0; i < 2000; ++i) norm.update(x);
  EXPECT_NEAR(norm.scale(), 90.0f, 1e-3);
}

TEST(RunningNormalizer, MatchesEmaFormula) {
  RunningNormalizer norm(0.1f, 1.0f);
  const std::vector<float> first = {1, 3};  // mean 2, variance 1: taken as is
  norm.update(first);
  EXPECT_FLOAT_EQ(norm.mean(), 2.0f);
  EXPECT_FLOAT_EQ(norm.variance(), 1.0f);
  const std::vector<float> second = {10, 10, 10, 10};  // mean 10, variance 0
  norm.update(second);
  EXPECT_NEAR(norm.mean(), 0.9f * 2 + 0.1f * 10, 1e-6);
  EXPECT_NEAR(norm.variance(), 0.9f, 1e-6);
  std::vector<float> g = {4.0f};
  norm.normalize(g);
  EXPECT_NEAR(g[0], (4.0f - 2.8f) / (std::sqrt(0.9f) + 1.0f), 1e-6);
}

TEST(RunningNormalizer, StateRoundTrips) {
  RunningNormalizer a(0.1f, 1.0f), b(0.1f, 1.0f);
  const std::vector<float> batch = {1, 2, 7};
  a.update(batch);
  b.set_state(a.state());
  a.update(batch);
  b.update(batch);
  EXPECT_EQ(a.mean(), b.mean());
  EXPECT_EQ(a.variance(), b.variance());
}

}  // namespace
}  // namespace indrive::agent
