// The protocol's rules for one episode, the same wherever an episode is evaluated (the
// evaluator, the local trainer's evaluation): which towns and routes a grid may name, the step
// budget of a route, route completion, the environment of protocol episodes and the verdict
// written as a CSV row.
#pragma once

#include <cstdint>
#include <string>

#include "indrive/actor/eval_protocol.h"
#include "indrive/basics/episode_csv.h"
#include "indrive/envserver/env.h"

namespace indrive::actor {

// Throws EvalError unless every town is a built-in name, an existing map file or grid:<seed>,
// and every route is one of the town's routes (env::town_route_names); the message lists the
// allowed values.
void check_grid_names(const ProtocolGrid& grid);
// The grid's routes from eval.routes: "all" gives each town its own routes
// (ProtocolGrid::town_routes), a list names the same routes on every town.
void set_grid_routes(ProtocolGrid& grid, const std::string& routes,
                     const env::TownOptions& options = {});

// Step budget of a route: ceil(slack * length_m / (speed_mps * dt_s)). With the defaults
// (3 m/s, the slower task speed, and 1.5x slack at 10 Hz) that is 5 steps per metre: 3,245 steps
// for town01's longest loop (649 m), where a fixed 1,000 steps (100 s) covers 300-600 m at
// 3-6 m/s, less than one lap.
int route_step_budget(double length_m, double speed_mps = 3.0, double slack = 1.5,
                      double dt_s = 0.1);
// The fraction of the route an episode drove, in [0, 1]: progress_m / length_m (the route's
// length, set back from its last junction on a point-to-point route), and 1 when the
// destination event fired (within kDestinationRadiusM of the terminal waypoint, or a lap).
double route_completion(double progress_m, double length_m, std::uint32_t events);
// The env config for protocol episodes: the protocol's step budget ends them, so the training
// time limit (env.time_limit_steps) is lifted out of its way; the events follow the protocol's
// rules.
env::EnvConfig protocol_env_config(env::EnvConfig config,
                                   EvalProtocol protocol = EvalProtocol::kStrict);

// The protocol's verdict on one episode of `spec`, as a CSV row without the run-level fields
// (run id, method, eval kind, task, seeds of training, policy version): success means the
// destination event with no failure event; otherwise the failure events name the reason.
// `events`: EventBit bits of the last step (kTimeLimit included when the budget ran out).
EpisodeRecord protocol_record(const EpisodeSpec& spec, std::uint32_t events, int steps,
                              double route_completion, double episode_return);

// What a training episode (a training actor's or the local trainer's) drew, and its return.
struct TrainingEpisode {
  std::string town;
  std::string route;  // empty: random spawns (pretraining)
  int density = 0;
  int traffic_seed = 0;
  int spawn_seed = 0;
  double route_length_m = 0.0;  // the route's length; 0 without a route
  double episode_return = 0.0;  // the task reward summed over its steps (0 in pretraining)
};

// A finished training episode as a CSV row, eval_kind "training", without the run-level fields
// (run id, method, task, seed, policy version, episode index). On a route the verdict and the
// route completion are the protocol's (success: the destination with no failure event); without
// a route an episode succeeds when nothing but the time limit ended it, and its completion is 0.
// `last`: the episode's last env result.
EpisodeRecord training_record(const TrainingEpisode& episode, const env::StepResult& last);

}  // namespace indrive::actor
