#include "indrive/actor/eval_protocol_episode.h"

#include <optional>

#include "indrive/actor/actor_config.h"
#include "indrive/actor/episode_video.h"
#include "indrive/actor/eval_protocol_record.h"
#include "indrive/basics/check.h"
#include "indrive/envserver/events.h"

namespace indrive::actor {

ProtocolEpisodeOptions protocol_episode_options(const config::Config& config,
                                                const std::filesystem::path& video_dir) {
  const EvalConfig eval = eval_config(config);
  return {.protocol = parse_protocol(eval.protocol),
          .budget_speed_mps = eval.budget_speed_mps,
          .budget_slack = eval.budget_slack,
          .code_budget_steps = eval.indrive_code_budget_steps,
          .video_episodes = eval.video_episodes,
          .video_dir = video_dir};
}

EpisodeOutcome run_protocol_episode(env::Env& env, EpisodePolicy& policy, const EpisodeSpec& spec,
                                    const ProtocolEpisodeOptions& options,
                                    const std::atomic<bool>& stop) {
  env::StepResult step = env.reset({.town = spec.town,
                                    .route = spec.route,
                                    .density = spec.density,
                                    .traffic_seed = static_cast<std::uint64_t>(spec.traffic_seed),
                                    .spawn_seed = static_cast<std::uint64_t>(spec.spawn_seed)});
  const env::Route* route = env.route();
  INDRIVE_CHECK(route != nullptr) << "an evaluation reset must place the ego on its route";
  const bool code_rules = env.config().events.rules == env::EventRules::kIndriveCode;
  INDRIVE_CHECK(code_rules == (options.protocol == EvalProtocol::kIndriveCode))
      << "the env's event rules are not those of protocol " << protocol_name(options.protocol)
      << " (build it with protocol_env_config)";
  const int budget =
      options.protocol == EvalProtocol::kIndriveCode
          ? options.code_budget_steps
          : route_step_budget(route->length_m(), options.budget_speed_mps, options.budget_slack);
  policy.begin(env, spec);
  std::optional<EpisodeVideo> video;
  if (spec.episode < options.video_episodes) {
    video.emplace(episode_video_path(options.video_dir, spec), env, spec, budget);
    video->add(env, step);
  }
  EpisodeOutcome outcome;
  while (!step.is_last && step.step < budget && !stop.load()) {
    step = env.step(policy.act(env, step));
    outcome.episode_return += step.reward.value_or(0.0);
    if (video) video->add(env, step);
  }
  outcome.stopped = !step.is_last && step.step < budget;
  outcome.events = step.events;
  const bool budget_ran_out = !step.is_last && !outcome.stopped;
  if (budget_ran_out) outcome.events |= env::kTimeLimit;
  outcome.steps = step.step;
  outcome.route_completion =
      route_completion(step.route_progress_m, route->length_m(), outcome.events);
  outcome.lane_invasions = env.events().lane_invasions();
  outcome.protocol = options.protocol;
  if (video) video->finish(outcome.events, budget_ran_out);
  return outcome;
}

EpisodeRecord protocol_record(const EpisodeSpec& spec, const EpisodeOutcome& outcome) {
  EpisodeRecord record = protocol_record(spec, outcome.events, outcome.steps,
                                         outcome.route_completion, outcome.episode_return);
  record.protocol = protocol_name(outcome.protocol);
  record.lane_invasions = outcome.lane_invasions;
  return record;
}

}  // namespace indrive::actor
