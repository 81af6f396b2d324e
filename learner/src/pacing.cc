#include "indrive/learner/pacing.h"

#include <utility>

namespace indrive::learner {
namespace {

double unix_time_s() {
  return std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
}

}  // namespace

Pacer::Pacer(dds::EndpointSet& endpoints, std::string run_id)
    : run_id_(std::move(run_id)),
      allowances_(endpoints.writer<msg::StepAllowance>()),
      heartbeats_(endpoints.writer<msg::Heartbeat>()) {}

bool Pacer::publish(const PacingState& state, bool force) {
  const double since_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - last_).count();
  const bool changed =
      state.allowed != published_allowance_ || state.env_steps != published_received_;
  if (!force && !(changed && since_s > 0.005) && since_s < 0.1) return false;
  msg::StepAllowance allowance;
  allowance.run_id(run_id_);
  allowance.total_env_steps(state.allowed);
  allowance.replay_ratio(state.replay_ratio);
  allowance.learner_epoch(state.learner_epoch);
  allowance.policy_version(state.policy_version);
  dds::seal(allowance);
  allowances_.write(allowance);

  msg::Heartbeat beat;
  beat.role(msg::ROLE_LEARNER);
  beat.id(0);
  beat.run_id(run_id_);
  beat.state(state.done ? "done" : "running");
  beat.policy_version(state.policy_version);
  beat.env_steps(static_cast<std::uint64_t>(state.env_steps));
  beat.updates(static_cast<std::uint64_t>(state.updates));
  beat.dropped_messages(state.dropped_chunks);
  beat.wall_time_s(unix_time_s());
  dds::seal(beat);
  heartbeats_.write(beat);
  published_allowance_ = state.allowed;
  published_received_ = state.env_steps;
  last_ = std::chrono::steady_clock::now();
  return true;
}

}  // namespace indrive::learner
