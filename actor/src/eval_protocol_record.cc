#include "indrive/actor/eval_protocol_record.h"

#include <algorithm>
#include <cmath>
#include <filesystem>

#include "indrive/basics/check.h"
#include "indrive/envserver/events.h"
#include "indrive/envserver/town.h"
#include "text.h"

namespace indrive::actor {

void check_grid_names(const ProtocolGrid& grid) {
  const std::vector<std::string> builtin = env::builtin_towns();
  for (const std::string& town : grid.towns) {
    const bool known = std::find(builtin.begin(), builtin.end(), town) != builtin.end() ||
                       town.starts_with("grid:") || std::filesystem::is_regular_file(town);
    if (!known) {
      throw EvalError("unknown evaluation town '" + town + "'; use a built-in town (" +
                      join(builtin) + "), a path to a .net.xml or .xodr map, or grid:<seed>");
    }
  }
  for (const std::string& town : grid.towns) {
    std::vector<std::string> names;
    try {
      names = env::town_route_names(town);
    } catch (const std::exception& error) {
      throw EvalError("evaluation town '" + town + "': " + error.what());
    }
    for (const std::string& route : grid.routes_of(town)) {
      if (std::find(names.begin(), names.end(), route) == names.end()) {
        throw EvalError("unknown evaluation route '" + route + "' on " + town + "; it has " +
                        join(names) + " (eval.routes: all takes every town's own routes)");
      }
    }
  }
}

void set_grid_routes(ProtocolGrid& grid, const std::string& routes,
                     const env::TownOptions& options) {
  grid.town_routes.clear();
  if (routes != "all") {
    grid.routes = split_list(routes);
    return;
  }
  grid.routes.clear();
  for (const std::string& town : grid.towns) {
    try {
      grid.town_routes[town] = env::town_route_names(town, options);
    } catch (const std::exception& error) {
      throw EvalError("evaluation town '" + town + "': " + error.what());
    }
  }
  // Every town reads its own list; `routes` keeps the first town's, so that the grid validates.
  if (!grid.towns.empty()) grid.routes = grid.town_routes[grid.towns.front()];
}

int route_step_budget(double length_m, double speed_mps, double slack, double dt_s) {
  INDRIVE_CHECK(length_m >= 0.0 && speed_mps > 0.0 && slack > 0.0 && dt_s > 0.0)
      << "route_step_budget(" << length_m << ", " << speed_mps << ", " << slack << ", " << dt_s
      << ")";
  return std::max(1, static_cast<int>(std::ceil(slack * length_m / (speed_mps * dt_s) - 1e-9)));
}

double route_completion(double progress_m, double length_m, std::uint32_t events) {
  if ((events & env::kDestination) != 0) return 1.0;
  if (length_m <= 0.0) return 0.0;
  return std::clamp(progress_m / length_m, 0.0, 1.0);
}

env::EnvConfig protocol_env_config(env::EnvConfig config, EvalProtocol protocol) {
  config.events.time_limit_steps = std::numeric_limits<int>::max() / 2;
  config.events.rules = protocol == EvalProtocol::kIndriveCode ? env::EventRules::kIndriveCode
                                                               : env::EventRules::kStrict;
  return config;
}

EpisodeRecord protocol_record(const EpisodeSpec& spec, std::uint32_t events, int steps,
                              double route_completion, double episode_return) {
  // An env_fault is reported as the reason so that reports can count it apart.
  const std::uint32_t failures = events & (env::kFailureEvents | env::kEnvFault);
  EpisodeRecord record;
  record.town = spec.town;
  record.route = spec.route;
  record.density = spec.density;
  record.traffic_seed = spec.traffic_seed;
  record.spawn_seed = spec.spawn_seed;
  record.episode = spec.episode;
  record.success = (events & env::kDestination) != 0 && failures == 0;
  record.failure_reason = record.success ? "" : env::event_names(failures);
  record.steps = steps;
  record.route_completion = route_completion;
  record.episode_return = episode_return;
  return record;
}

EpisodeRecord training_record(const TrainingEpisode& episode, const env::StepResult& last) {
  EpisodeRecord record;
  record.eval_kind = "training";
  record.town = episode.town;
  record.route = episode.route;
  record.density = episode.density;
  record.traffic_seed = episode.traffic_seed;
  record.spawn_seed = episode.spawn_seed;
  record.steps = static_cast<int>(last.step);
  record.episode_return = episode.episode_return;
  std::uint32_t failures = last.events & (env::kFailureEvents | env::kEnvFault);
  if (episode.route.empty()) {
    failures &= ~env::kTimeLimit;
    record.success = failures == 0;
  } else {
    record.success = (last.events & env::kDestination) != 0 && failures == 0;
    record.route_completion =
        episode.route_length_m > 0.0
            ? route_completion(last.route_progress_m, episode.route_length_m, last.events)
            : 0.0;
  }
  record.failure_reason = failures == 0 ? "" : env::event_names(failures);
  return record;
}
}  // namespace indrive::actor
