#include "indrive/service/training_metrics.h"

#include <algorithm>
#include <nlohmann/json.hpp>
#include <sstream>

#include "indrive/basics/run_dir.h"

namespace indrive::service {

void MetricsInterval::restart(const TrainingProgress& progress) {
  start_ = std::chrono::steady_clock::now();
  start_steps_ = progress.env_steps;
  start_updates_ = progress.updates;
}

bool MetricsInterval::due(const TrainingProgress& progress, double interval_s,
                          std::int64_t every_steps) const {
  return elapsed_s() >= interval_s ||
         passed_multiple(start_steps_, progress.env_steps, every_steps);
}

double MetricsInterval::elapsed_s() const {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
}

nlohmann::json MetricsInterval::fields(const TrainingProgress& progress) const {
  const double elapsed = std::max(elapsed_s(), 1e-9);
  const double ratio = progress.env_steps > 0
                           ? static_cast<double>(progress.updates) * progress.steps_per_update /
                                 static_cast<double>(progress.env_steps)
                           : 0.0;
  return {{"env_steps", progress.env_steps},
          {"updates", progress.updates},
          {"env_steps_per_s", (progress.env_steps - start_steps_) / elapsed},
          {"updates_per_s", (progress.updates - start_updates_) / elapsed},
          {"replay_ratio", ratio},
          {"policy_version", progress.policy_version},
          {"replay_size", progress.replay_size},
          {"learner_epoch", progress.learner_epoch},
          {"phase", std::string(agent::to_string(progress.phase))}};
}

std::string MetricsInterval::console_head(const TrainingProgress& progress) const {
  const double elapsed = std::max(elapsed_s(), 1e-9);
  std::ostringstream line;
  line.precision(4);
  line << "steps " << progress.env_steps << " | updates " << progress.updates << " | "
       << (progress.env_steps - start_steps_) / elapsed << " steps/s | "
       << (progress.updates - start_updates_) / elapsed << " upd/s";
  return line.str();
}

}  // namespace indrive::service
