// One protocol episode, run the same way by the evaluator and by the local trainer's
// evaluation: a reset on the spec's town and route with its traffic and spawn seeds, the
// route's step budget, the policy acting every step, a video of the first episodes of a cell,
// the time limit when the budget runs out, and route completion.
//
//   const ProtocolEpisodeOptions options = protocol_episode_options(config, run_dir / "videos");
//   const EpisodeOutcome outcome = run_protocol_episode(env, *policy, spec, options, stop);
//   if (outcome.stopped) return;                  // cut short: not a protocol result
//   EpisodeRecord record = protocol_record(spec, outcome);
#pragma once

#include <atomic>
#include <cstdint>
#include <filesystem>

#include "indrive/actor/eval_protocol.h"
#include "indrive/actor/policies.h"
#include "indrive/basics/config.h"
#include "indrive/basics/episode_csv.h"
#include "indrive/envserver/env.h"

namespace indrive::actor {

// The eval.* keys of an episode.
struct ProtocolEpisodeOptions {
  EvalProtocol protocol = EvalProtocol::kStrict;  // eval.protocol
  double budget_speed_mps = 3.0;                  // eval.budget_speed_mps (strict)
  double budget_slack = 1.5;                      // eval.budget_slack (strict)
  int code_budget_steps = 30000;                  // eval.indrive_code_budget_steps (indrive_code)
  int video_episodes = 0;           // eval.video_episodes: record episodes 0..N-1 of every cell
  std::filesystem::path video_dir;  // where the videos go (<run>/videos)
};
// Reads them from a run's configuration.
ProtocolEpisodeOptions protocol_episode_options(const config::Config& config,
                                                const std::filesystem::path& video_dir);

// How an episode ended.
struct EpisodeOutcome {
  bool stopped = false;      // `stop` was set before the protocol ended it: discard the episode
  std::uint32_t events = 0;  // the last step's events, kTimeLimit added when the budget ran out
  int steps = 0;
  double route_completion = 0.0;
  double episode_return = 0.0;
  int lane_invasions = 0;  // entries into the lane-invasion condition (events.h)
  EvalProtocol protocol = EvalProtocol::kStrict;
};

// Runs episode `spec` in `env` (built with protocol_env_config for options.protocol) with
// `policy`: up to the route's step budget (strict) or options.code_budget_steps (indrive_code).
EpisodeOutcome run_protocol_episode(env::Env& env, EpisodePolicy& policy, const EpisodeSpec& spec,
                                    const ProtocolEpisodeOptions& options,
                                    const std::atomic<bool>& stop);

// The verdict of a finished episode as a CSV row without the run-level fields, its protocol and
// lane invasions included.
EpisodeRecord protocol_record(const EpisodeSpec& spec, const EpisodeOutcome& outcome);

}  // namespace indrive::actor
