#include "indrive/learner/learner_config.h"

#include <algorithm>

namespace indrive::learner {

LearnerConfig learner_config(const config::Config& c) {
  return {
      .seed = c.get<std::int64_t>("run.seed"),
      .budget_env_steps = c.get<std::int64_t>("run.budget_env_steps"),
      .replay_ratio = c.get<double>("learner.replay_ratio"),
      .async = c.get<bool>("learner.async"),
      .allowance_slack = std::max(c.get<std::int64_t>("learner.allowance_slack"),
                                  c.get<std::int64_t>("actor.chunk_length")),
      .snapshot_every = c.get<std::int64_t>("learner.snapshot_every"),
      .announce_s = c.get<double>("learner.announce_s"),
      .snapshot_hold_s = c.get<double>("learner.snapshot_hold_s"),
      .log_interval_s = c.get<double>("learner.log_interval_s"),
      .log_every_env_steps = c.get<std::int64_t>("learner.log_every_env_steps"),
      .checkpoint_s = c.get<double>("learner.checkpoint_minutes") * 60.0,
      .checkpoint_keep = c.get<int>("learner.checkpoint_keep"),
      .init_checkpoint = c.get<std::string>("learner.init_checkpoint"),
      .dashboard_s = c.get<double>("learner.dashboard_s"),
  };
}

}  // namespace indrive::learner
