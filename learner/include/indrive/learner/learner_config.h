// The learner's settings as one typed value, read once from the run's configuration: the
// `learner.*` keys and the `run.*` keys a training run reads. The keys themselves (defaults,
// ranges, help) are declared with every other key of the run in common/service/src/run_config.cc
// (docs/architecture.md, section 5); this is the learner folder's typed view of them, used by
// indrive-learner and indrive-train-local alike.
//
//   const LearnerConfig settings = learner_config(service.config());
//   RateLimiter rate({.replay_ratio = settings.replay_ratio, ...});
#pragma once

#include <cstdint>
#include <string>

#include "indrive/basics/config.h"

namespace indrive::learner {

struct LearnerConfig {
  std::int64_t seed = 0;              // run.seed: the training seed the results carry
  std::int64_t budget_env_steps = 0;  // run.budget_env_steps: the run's end (0: none)
  double replay_ratio = 32.0;         // replayed steps per env step
  bool async = false;                 // the rate limit lifted (throughput runs)
  // Env steps actors may run ahead of training: learner.allowance_slack, and at least one chunk
  // (actor.chunk_length), so an actor can always finish the chunk it holds.
  std::int64_t allowance_slack = 64;
  std::int64_t snapshot_every = 10;  // updates between snapshots
  double announce_s = 1.0;           // seconds between announces
  double snapshot_hold_s = 10.0;     // longest wait of a due snapshot for the last one's readers
  double log_interval_s = 5.0;       // seconds between metrics lines
  std::int64_t log_every_env_steps = 1000;  // also a line at each multiple (0: off)
  double checkpoint_s = 300.0;              // learner.checkpoint_minutes, in seconds
  int checkpoint_keep = 3;
  std::string init_checkpoint;  // a pretraining checkpoint to finetune from (empty: none)
  double dashboard_s = 30.0;    // rewrites of the run's page by a companion process (0: none)

  bool operator==(const LearnerConfig&) const = default;
};

// Reads the settings from a resolved run configuration (whose values are already checked).
LearnerConfig learner_config(const config::Config& config);

}  // namespace indrive::learner
