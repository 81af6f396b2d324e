#include "indrive/actor/actor_config.h"

namespace indrive::actor {

ActorConfig actor_config(const config::Config& c) {
  return {.chunk_length = c.get<int>("actor.chunk_length"),
          .heartbeat_s = c.get<double>("actor.heartbeat_s"),
          .request_after_s = c.get<double>("actor.request_after_s"),
          .rejoin_after_s = c.get<double>("actor.rejoin_after_s"),
          .rejoin_max_s = c.get<double>("actor.rejoin_max_s"),
          .coverage_period_s = c.get<double>("actor.coverage_period_s")};
}

EvalConfig eval_config(const config::Config& c) {
  return {.towns = c.get<std::string>("eval.towns"),
          .routes = c.get<std::string>("eval.routes"),
          .densities = c.get<std::vector<double>>("eval.densities"),
          .episodes_per_cell = c.get<int>("eval.episodes_per_cell"),
          .policy = c.get<std::string>("eval.policy"),
          .snapshot_file = c.get<std::string>("eval.snapshot_file"),
          .head = c.get<std::string>("eval.head"),
          .kind = c.get<std::string>("eval.kind"),
          .oracle_brake = c.get<bool>("eval.oracle_brake"),
          .oracle_speed_mps = c.get<double>("eval.oracle_speed_mps"),
          .wait_for_done = c.get<bool>("eval.wait_for_done"),
          .snapshot_timeout_s = c.get<double>("eval.snapshot_timeout_s"),
          .learner_silence_s = c.get<double>("eval.learner_silence_s"),
          .continuous = c.get<bool>("eval.continuous"),
          .every_k = c.get<int>("eval.every_k"),
          .resume = c.get<bool>("eval.resume"),
          .protocol = c.get<std::string>("eval.protocol"),
          .indrive_code_budget_steps = c.get<int>("eval.indrive_code_budget_steps"),
          .budget_speed_mps = c.get<double>("eval.budget_speed_mps"),
          .budget_slack = c.get<double>("eval.budget_slack"),
          .video_episodes = c.get<int>("eval.video_episodes"),
          .probe_far_m = c.get<double>("eval.probe_far_m"),
          .probe_near_m = c.get<double>("eval.probe_near_m"),
          .probe_oracle_brake = c.get<bool>("eval.probe_oracle_brake")};
}

}  // namespace indrive::actor
