// The replay-ratio rate limit (ARCHITECTURE.md section 4), as pure arithmetic.
//
// The learner does one update of B x T replayed steps whenever
//   updates * B * T <= replay_ratio * env_steps_received,
// and tells the actors how many env steps they may have taken in total: enough for the next
// update to fall due, plus a slack of at least one chunk (a chunk is only sent when complete,
// so a smaller slack could stop every actor before its chunk reaches the learner). So the
// ratio holds whatever the speed of the machine, and in async mode the limit is lifted.
//
//   RateLimiter rate({.replay_ratio = 32, .steps_per_update = 8 * 16, .prefill = 500,
//                     .slack = 64});
//   while (updates < rate.updates_due(received)) train();
//   publish_allowance(rate.allowance(updates, fill_floor));
#pragma once

#include <cstdint>

namespace indrive::agent {

struct RateOptions {
  double replay_ratio = 32.0;         // replayed steps per env step
  std::int64_t steps_per_update = 1;  // batch x length
  std::int64_t prefill = 0;           // env steps before the first update
  std::int64_t slack = 64;            // env steps actors may run ahead of the next update
  bool async = false;                 // no limit on the actors
};

class RateLimiter {
 public:
  // Checks that the options are positive (a bug otherwise).
  explicit RateLimiter(RateOptions options);

  // Number of updates that should have been done after `received` env steps (0 before the
  // prefill is complete).
  std::int64_t updates_due(std::int64_t received) const;
  // Total env steps the actors may have taken when `updates` updates are done; `fill_floor`
  // is the env-step count up to which actors may always run (the end of the prefill, or of a
  // refill after a restart). Async mode returns the largest value.
  std::uint64_t allowance(std::int64_t updates, std::int64_t fill_floor) const;
  const RateOptions& options() const { return options_; }

 private:
  RateOptions options_;
};

}  // namespace indrive::agent
