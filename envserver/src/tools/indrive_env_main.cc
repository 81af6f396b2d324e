// indrive-env: run an episode of the driving environment, or draw a town with its routes.
//
//   indrive-env episode --town town01 --route straight --density 10 --policy follower
//                       --seed 1 --video out.mp4
//   indrive-env routes --town town01 --out town01.png
#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <iostream>
#include <map>
#include <memory>
#include <optional>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include "indrive/basics/log.h"
#include "indrive/envserver/bev.h"
#include "indrive/envserver/camera.h"
#include "indrive/envserver/env.h"
#include "indrive/envserver/follower.h"
#include "indrive/envserver/town.h"
#include "indrive/envserver/video.h"

namespace {

using namespace indrive::env;

// A command-line mistake: printed with the usage.
class UsageError : public std::invalid_argument {
 public:
  using std::invalid_argument::invalid_argument;
};

constexpr const char* kUsage = R"(usage:
  indrive-env episode [--town town01] [--route NAME] [--density 0|5|10|20]
                      [--policy random|follower] [--seed N] [--spawn-seed N]
                      [--target-speed 5] [--size 128] [--mode libsumo|libtraci]
                      [--task lane_following|collision_avoidance] [--video out.mp4]
                      [--quiet]
  indrive-env routes --town town01 --out town01.png [--route-set right|left]
      (lists the routes of the route set (env.route_set), warns of any approach two routes leave by different exits, and
       bounds what a policy that sees no route can follow: junctions that offer the same
       exits but where routes take different ones)
Towns: town01, town02 (ours), carla_town01, carla_town02 (CARLA's), a .net.xml or .xodr file,
grid:<seed>. Routes: straight, right_loop, left_loop, two_turn on ours and derived ones; the
CARLA towns' are the public InDRiVE code's (`indrive-env routes` lists them: straight_1, ...).
Empty: random spawn, no route. The follower policy needs a route.)";

// Flags of the form --name value (or --name alone for booleans).
std::map<std::string, std::string> parse_flags(int argc, char** argv, int first) {
  std::map<std::string, std::string> flags;
  for (int i = first; i < argc; ++i) {
    std::string arg = argv[i];
    if (arg.rfind("--", 0) != 0) throw UsageError("unexpected argument '" + arg + "'");
    arg = arg.substr(2);
    if (i + 1 < argc && std::string(argv[i + 1]).rfind("--", 0) != 0) {
      flags[arg] = argv[++i];
    } else {
      flags[arg] = "true";
    }
  }
  return flags;
}

std::string take(std::map<std::string, std::string>& flags, const std::string& name,
                 const std::string& fallback) {
  auto it = flags.find(name);
  if (it == flags.end()) return fallback;
  std::string value = it->second;
  flags.erase(it);
  return value;
}

long long take_int(std::map<std::string, std::string>& flags, const std::string& name,
                   long long fallback) {
  const std::string text = take(flags, name, std::to_string(fallback));
  try {
    std::size_t used = 0;
    const long long value = std::stoll(text, &used);
    if (used != text.size()) throw std::invalid_argument(text);
    return value;
  } catch (const std::exception&) {
    throw UsageError("--" + name + " needs an integer, got '" + text + "'");
  }
}

void reject_leftovers(const std::map<std::string, std::string>& flags) {
  if (!flags.empty()) throw UsageError("unknown flag --" + flags.begin()->first);
}

int run_routes(std::map<std::string, std::string> flags) {
  const std::string town_name = take(flags, "town", "town01");
  const std::string out = take(flags, "out", town_name + ".png");
  TownOptions options;
  options.route_set = take(flags, "route-set", "right");
  reject_leftovers(flags);
  const Town town = load_town(town_name, options);
  draw_town(town.net, town.routes, town.spawns, out);
  std::printf("%s: %zu lanes, %zu routes, %zu spawn points -> %s\n", town_name.c_str(),
              town.net.lanes().size(), town.routes.size(), town.spawns.size(), out.c_str());
  for (const Route& route : town.routes) {
    // Route::turns() lists every junction crossed; going straight through one is no turn.
    const auto turns = std::count_if(route.turns().begin(), route.turns().end(),
                                     [](TurnDirection d) { return d != TurnDirection::kStraight; });
    std::printf("  %-10s %7.1f m %s, %td turns, %zu junctions\n", route.name().c_str(),
                route.length_m(), route.is_loop() ? "loop" : "point to point", turns,
                route.turns().size());
  }
  // Derived routes keep only candidates the scripted follower drives (route_check.h).
  if (!town.dropped_routes.empty()) {
    std::printf("dropped %zu derived candidate(s) the scripted follower cannot drive alone:\n",
                town.dropped_routes.size());
    for (const std::string& line : town.dropped_routes) std::printf("  %s\n", line.c_str());
  }
  // A policy that sees no route cannot leave one approach by two exits (see routes.h).
  const std::vector<RouteConflict> conflicts = route_conflicts(town.routes);
  if (conflicts.empty()) {
    std::printf("  conflict-free: no approach is left by two different exits\n");
  }
  for (const RouteConflict& conflict : conflicts) {
    std::printf("  warning: route conflict at %s\n", conflict.message.c_str());
  }
  // The stricter bound: the policy sees a junction's exits, not its edge ids (see routes.h).
  std::vector<std::string> names;
  for (const Route& route : town.routes) names.push_back(route.name());
  const LayoutRuleBound bound = layout_rule_bound(names, route_choices(town.net, town.routes));
  std::string followed;
  for (const std::string& name : bound.routes_followed)
    followed += (followed.empty() ? "" : ", ") + name;
  std::printf(
      "  layout bound: a policy that picks its exit by what a junction offers follows at most\n"
      "  %zu of %d routes (%s): average SR <= %.0f%% unless it tells look-alike junctions\n"
      "  apart by what it sees or remembers (indrive-route-probe measures whether a\n"
      "  snapshot can)\n",
      bound.routes_followed.size(), bound.route_count, followed.c_str(),
      bound.route_count > 0 ? 100.0 * bound.routes_followed.size() / bound.route_count : 0.0);
  for (const std::string& line : bound.lookalikes) std::printf("    look-alike %s\n", line.c_str());
  return 0;
}

int run_episode(std::map<std::string, std::string> flags) {
  EnvConfig config;
  config.town = take(flags, "town", "town01");
  config.task = take(flags, "task", "");
  config.sumo.mode = parse_sumo_mode(take(flags, "mode", "libsumo"));
  const int size = static_cast<int>(take_int(flags, "size", 128));
  config.camera.width = size;
  config.camera.height = size;
  ResetOptions reset;
  reset.route = take(flags, "route", "");
  reset.density = static_cast<int>(take_int(flags, "density", 10));
  reset.traffic_seed = static_cast<std::uint64_t>(take_int(flags, "seed", 1));
  reset.spawn_seed = static_cast<std::uint64_t>(take_int(flags, "spawn-seed", reset.traffic_seed));
  const std::string policy = take(flags, "policy", "random");
  const double target_speed = std::stod(take(flags, "target-speed", "5"));
  const std::string video_path = take(flags, "video", "");
  const bool quiet = take(flags, "quiet", "false") == "true";
  reject_leftovers(flags);
  if (policy != "random" && policy != "follower") {
    throw UsageError("--policy must be random or follower, got '" + policy + "'");
  }
  if (policy == "follower" && reset.route.empty()) {
    throw UsageError("--policy follower needs --route");
  }

  Env env(config);
  StepResult result = env.reset(reset);
  std::optional<WaypointFollower> follower;
  if (policy == "follower") {
    follower.emplace(*env.route(), config.ego, FollowerConfig{.target_speed_mps = target_speed});
    follower->reset();
  }
  std::mt19937_64 rng(reset.traffic_seed * 7919 + 17);

  std::unique_ptr<VideoWriter> video;
  std::unique_ptr<BirdsEyeView> bev;
  std::vector<Eigen::Vector2d> route_line;
  if (!video_path.empty()) {
    bev = std::make_unique<BirdsEyeView>(BevConfig{}, env.scene());
    if (env.route() != nullptr) {
      for (const Waypoint& w : env.route()->waypoints()) route_line.push_back(w.position);
    }
  }
  auto record = [&](const StepResult& r) {
    if (!bev) return;
    const cv::Mat camera_rgb = colorize(r.observation);
    const cv::Mat bev_rgb = bev->render(env.ego_box(), env.traffic_boxes(),
                                        {.route = route_line, .alert = is_failure(r.events)});
    char speed[64];
    std::snprintf(speed, sizeof(speed), "%.1f m/s", r.ego.speed_mps);
    const std::vector<std::string> lines = {"step " + std::to_string(r.step), speed,
                                            event_names(r.events)};
    const cv::Mat frame = compose_frame(camera_rgb, bev_rgb, lines);
    if (!video) video = std::make_unique<VideoWriter>(video_path, frame.size(), 10.0);
    video->write(frame);
  };
  record(result);

  double reward_sum = 0.0;
  while (!result.is_last) {
    const int action = follower ? follower->act(env.ego()) : static_cast<int>(rng() % kNumActions);
    result = env.step(action);
    if (result.reward) reward_sum += *result.reward;
    record(result);
    if (!quiet && (result.step % 100 == 0 || result.events != 0)) {
      std::printf("step %4d  action %d  speed %4.1f m/s  progress %6.1f m  traffic %2d  %s\n",
                  result.step, action, result.ego.speed_mps, result.route_progress_m,
                  env.traffic_count(), event_names(result.events).c_str());
    }
  }
  if (video) video->close();

  const EnvTiming& t = env.timing();
  std::printf("episode: %d steps, end %s (%s), route progress %.1f m", result.step,
              event_names(result.events).c_str(),
              !is_failure(result.events) ? "success" : "failure", result.route_progress_m);
  if (!config.task.empty()) std::printf(", return %.2f", reward_sum);
  std::printf(
      "\n%.0f steps/s (sumo %.0f us, traffic %.0f us, render %.0f us, events %.0f us per step)\n",
      t.steps / (t.sumo_s + t.traffic_s + t.render_s + t.events_s), 1e6 * t.sumo_s / t.steps,
      1e6 * t.traffic_s / t.steps, 1e6 * t.render_s / t.steps, 1e6 * t.events_s / t.steps);
  if (video) std::printf("video: %s (%d frames)\n", video_path.c_str(), video->frames_written());
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  indrive::log::set_level(indrive::log::Level::kWarn);
  try {
    if (argc < 2) throw UsageError("missing command");
    const std::string command = argv[1];
    auto flags = parse_flags(argc, argv, 2);
    if (command == "episode") return run_episode(std::move(flags));
    if (command == "routes") return run_routes(std::move(flags));
    if (command == "--help" || command == "help") {
      std::puts(kUsage);
      return 0;
    }
    throw UsageError("unknown command '" + command + "'");
  } catch (const UsageError& e) {
    std::fprintf(stderr, "indrive-env: %s\n%s\n", e.what(), kUsage);
    return 2;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "indrive-env: %s\n", e.what());
    return 1;
  }
}
