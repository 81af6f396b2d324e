// Returns and normalisers of the actor-critic and the intrinsic rewards, on plain arrays so
// that they can be tested against hand-computed values.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

namespace indrive::agent {

// Lambda-returns of an imagined trajectory, computed backwards from the bootstrap value:
//   R_H = v_H;  R_t = r_t + gamma * c_t * ((1 - lambda) * v_{t+1} + lambda * R_{t+1}).
// r_t and c_t belong to the transition from state t to state t+1 (predicted at state t+1).
// rewards and continues are (H, N) row-major; values is (H + 1, N); result is (H, N).
std::vector<float> lambda_returns(std::span<const float> rewards, std::span<const float> continues,
                                  std::span<const float> values, int horizon, int n, float gamma,
                                  float lambda);

// Linear-interpolation quantile of `values` at q in [0, 1] (the numpy default).
float quantile(std::span<const float> values, float q);

// DreamerV3's return normaliser: EMA of the 5th and 95th percentile of the returns, and a scale
// max(floor, high - low) that advantages are divided by, so that large returns are scaled down
// but small ones are not scaled up.
class ReturnNormalizer {
 public:
  // Percentiles in [0, 1], EMA decay and scale floor (0.05, 0.95, 0.99, 1.0 by default).
  ReturnNormalizer(float low = 0.05f, float high = 0.95f, float decay = 0.99f, float floor = 1.0f);
  // Moves the EMA percentiles towards those of `returns` (any shape, flattened).
  void update(std::span<const float> returns);
  // Current max(floor, high - low).
  float scale() const;
  // Current EMA low and high percentiles.
  float low() const { return low_; }
  float high() const { return high_; }
  // State for checkpoints: {low, high}.
  std::vector<float> state() const { return {low_, high_}; }
  void set_state(std::span<const float> state);

 private:
  float low_q_, high_q_, decay_, floor_;
  float low_ = 0.0f, high_ = 0.0f;
};

// Norm(g) = (g - mu) / (sigma + eps) with mu and sigma^2 exponential moving averages of the
// batch mean and batch variance at rate rho. The first update sets them to the batch values.
class RunningNormalizer {
 public:
  RunningNormalizer(float rate = 0.01f, float eps = 1.0f);
  // Folds the mean and variance of `batch` into the running moments.
  void update(std::span<const float> batch);
  // Normalises `values` in place with the current moments.
  void normalize(std::span<float> values) const;
  float mean() const { return mean_; }
  float variance() const { return var_; }
  std::int64_t updates() const { return updates_; }
  // State for checkpoints: {mean, variance, updates}.
  std::vector<float> state() const { return {mean_, var_, static_cast<float>(updates_)}; }
  void set_state(std::span<const float> state);

 private:
  float rate_, eps_;
  float mean_ = 0.0f, var_ = 1.0f;
  std::int64_t updates_ = 0;
};

}  // namespace indrive::agent
