#include "indrive/agent/rate_limiter.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "indrive/basics/check.h"

namespace indrive::agent {

RateLimiter::RateLimiter(RateOptions options) : options_(options) {
  INDRIVE_CHECK(options_.replay_ratio > 0.0 && options_.steps_per_update > 0 &&
                options_.prefill >= 0 && options_.slack > 0)
      << "rate limiter options must be positive";
}

std::int64_t RateLimiter::updates_due(std::int64_t received) const {
  if (received < options_.prefill || received <= 0) return 0;
  return static_cast<std::int64_t>(
      std::floor(options_.replay_ratio * static_cast<double>(received) /
                 static_cast<double>(options_.steps_per_update)));
}

std::uint64_t RateLimiter::allowance(std::int64_t updates, std::int64_t fill_floor) const {
  if (options_.async) return std::numeric_limits<std::uint64_t>::max();
  // Smallest received count at which update number updates + 1 falls due.
  const double next = static_cast<double>(updates + 1) *
                      static_cast<double>(options_.steps_per_update) / options_.replay_ratio;
  const auto next_due = static_cast<std::int64_t>(std::ceil(next - 1e-9));
  const std::int64_t floor = std::max(fill_floor, options_.prefill);
  return static_cast<std::uint64_t>(std::max(next_due, floor) + options_.slack);
}

}  // namespace indrive::agent
