// What every training process (the learner, the local trainer) writes at the head of its
// metrics lines and console lines, with the interval bookkeeping between lines, so that the
// curves of distributed and local runs compare key for key and the two never drift apart.
//
//   MetricsInterval interval;
//   interval.restart(progress);                        // at the start of the loop
//   if (interval.due(progress, 5.0, 1000)) {           // 5 s passed or 1000 env steps crossed
//     nlohmann::json record = interval.fields(progress);  // + the process's own keys
//     progress_line(interval.console_head(progress) + " | ...");
//     interval.restart(progress);
//   }
#pragma once

#include <chrono>
#include <cstdint>
#include <nlohmann/json_fwd.hpp>
#include <string>

#include "indrive/agent/agent_config.h"

namespace indrive::service {

// Where training stands when a line is written.
struct TrainingProgress {
  std::int64_t env_steps = 0;
  std::int64_t updates = 0;
  std::uint64_t policy_version = 0;
  std::uint64_t learner_epoch = 0;
  std::int64_t replay_size = 0;
  std::int64_t steps_per_update = 1;  // replayed steps per update: batch * sequence length
  agent::Phase phase = agent::Phase::kPretrain;
};

class MetricsInterval {
 public:
  // Starts a new interval at `progress` now.
  void restart(const TrainingProgress& progress);
  // True when `interval_s` passed since the interval began, or the env steps crossed a
  // multiple of `every_steps` (0: only the time counts).
  bool due(const TrainingProgress& progress, double interval_s, std::int64_t every_steps) const;
  // Seconds since the interval began.
  double elapsed_s() const;
  // The env steps when the interval began.
  std::int64_t start_env_steps() const { return start_steps_; }
  // The shared keys of a line ending the interval: env_steps, updates, env_steps_per_s,
  // updates_per_s (over the interval), replay_ratio (over the run: updates * steps_per_update
  // / env_steps), policy_version, replay_size, learner_epoch, phase.
  nlohmann::json fields(const TrainingProgress& progress) const;
  // "steps N | updates M | X steps/s | Y upd/s", the start of a console line.
  std::string console_head(const TrainingProgress& progress) const;

 private:
  std::chrono::steady_clock::time_point start_ = std::chrono::steady_clock::now();
  std::int64_t start_steps_ = 0;
  std::int64_t start_updates_ = 0;
};

}  // namespace indrive::service
