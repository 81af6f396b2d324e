#include "indrive/agent/returns.h"

#include <algorithm>
#include <cmath>

#include "indrive/basics/check.h"

namespace indrive::agent {

std::vector<float> lambda_returns(std::span<const float> rewards, std::span<const float> continues,
                                  std::span<const float> values, int horizon, int n, float gamma,
                                  float lambda) {
  const std::size_t hn = static_cast<std::size_t>(horizon) * n;
  INDRIVE_CHECK_EQ(rewards.size(), hn);
  INDRIVE_CHECK_EQ(continues.size(), hn);
  INDRIVE_CHECK_EQ(values.size(), hn + n);
  std::vector<float> out(hn);
  for (int i = 0; i < n; ++i) {
    float next = values[static_cast<std::size_t>(horizon) * n + i];  // R_H = v_H
    for (int t = horizon - 1; t >= 0; --t) {
      const std::size_t k = static_cast<std::size_t>(t) * n + i;
      const float v_next = values[k + n];
      next = rewards[k] + gamma * continues[k] * ((1.0f - lambda) * v_next + lambda * next);
      out[k] = next;
    }
  }
  return out;
}

float quantile(std::span<const float> values, float q) {
  INDRIVE_CHECK(!values.empty()) << "quantile of no values";
  std::vector<float> sorted(values.begin(), values.end());
  std::sort(sorted.begin(), sorted.end());
  const double pos = static_cast<double>(q) * (sorted.size() - 1);
  const std::size_t lo = static_cast<std::size_t>(std::floor(pos));
  const std::size_t hi = std::min(lo + 1, sorted.size() - 1);
  const double frac = pos - lo;
  return static_cast<float>(sorted[lo] + frac * (sorted[hi] - sorted[lo]));
}

ReturnNormalizer::ReturnNormalizer(float low, float high, float decay, float floor)
    : low_q_(low), high_q_(high), decay_(decay), floor_(floor) {}

void ReturnNormalizer::update(std::span<const float> returns) {
  const float low = quantile(returns, low_q_);
  const float high = quantile(returns, high_q_);
  low_ = decay_ * low_ + (1.0f - decay_) * low;
  high_ = decay_ * high_ + (1.0f - decay_) * high;
}

float ReturnNormalizer::scale() const { return std::max(floor_, high_ - low_); }

void ReturnNormalizer::set_state(std::span<const float> state) {
  INDRIVE_CHECK_EQ(state.size(), 2u);
  low_ = state[0], high_ = state[1];
}

RunningNormalizer::RunningNormalizer(float rate, float eps) : rate_(rate), eps_(eps) {}

void RunningNormalizer::update(std::span<const float> batch) {
  INDRIVE_CHECK(!batch.empty()) << "normaliser update with no values";
  double sum = 0.0;
  for (float x : batch) sum += x;
  const double mean = sum / batch.size();
  double sq = 0.0;
  for (float x : batch) sq += (x - mean) * (x - mean);
  const double var = sq / batch.size();
  if (updates_ == 0) {
    mean_ = static_cast<float>(mean), var_ = static_cast<float>(var);
  } else {
    mean_ = static_cast<float>((1.0 - rate_) * mean_ + rate_ * mean);
    var_ = static_cast<float>((1.0 - rate_) * var_ + rate_ * var);
  }
  ++updates_;
}

void RunningNormalizer::normalize(std::span<float> values) const {
  const float denom = std::sqrt(std::max(var_, 0.0f)) + eps_;
  for (float& x : values) x = (x - mean_) / denom;
}

void RunningNormalizer::set_state(std::span<const float> state) {
  INDRIVE_CHECK_EQ(state.size(), 3u);
  mean_ = state[0], var_ = state[1], updates_ = static_cast<std::int64_t>(state[2]);
}

}  // namespace indrive::agent
