// Benchmark of the road-network work an environment step does: lane lookup, drivability,
// route tracking; plus the one-off costs of loading a town and building its static scene.
// Prints figures; asserts nothing.
#include <chrono>
#include <cstdio>
#include <random>

#include "indrive/basics/stopwatch.h"
#include "indrive/envserver/town.h"

namespace {

using Clock = std::chrono::steady_clock;
using indrive::seconds_since;

}  // namespace

int main(int argc, char** argv) {
  using namespace indrive::env;
  const std::string spec = argc > 1 ? argv[1] : "town01";
  TownOptions options;
  auto start = Clock::now();
  const Town town = load_town(spec, options);
  const double load_s = seconds_since(start);
  start = Clock::now();
  const StaticScene scene = build_static_scene(town.net);
  const double scene_s = seconds_since(start);
  std::printf(
      "%s: %zu lanes, %zu junctions; load %.1f ms (parse, routes, spawns), static scene "
      "%.1f ms (%zu polygons, %zu lines, %zu boxes)\n",
      spec.c_str(), town.net.lanes().size(), town.net.junctions().size(), 1e3 * load_s,
      1e3 * scene_s, scene.ground.size(), scene.lines.size(), scene.boxes.size());

  // Query points: jittered poses along the routes, as a driving ego produces them.
  std::mt19937 rng(1);
  std::normal_distribution<double> jitter(0.0, 1.5);
  std::vector<Pose2> poses;
  for (const Route& route : town.routes) {
    for (const Waypoint& w : route.waypoints()) {
      poses.push_back({w.position.x() + jitter(rng), w.position.y() + jitter(rng),
                       w.heading_rad + 0.1 * jitter(rng)});
    }
  }
  const int rounds = 200;
  long found = 0;
  start = Clock::now();
  for (int r = 0; r < rounds; ++r) {
    for (const Pose2& pose : poses)
      found += town.net.locate({pose.x_m, pose.y_m}, pose.yaw_rad).has_value();
  }
  const double locate_s = seconds_since(start) / (rounds * poses.size());
  long drivable = 0;
  start = Clock::now();
  for (int r = 0; r < rounds; ++r) {
    for (const Pose2& pose : poses) drivable += town.net.is_drivable({pose.x_m, pose.y_m});
  }
  const double drivable_s = seconds_since(start) / (rounds * poses.size());

  // Tracking: one lap of each route at 0.5 m per update.
  long updates = 0;
  start = Clock::now();
  for (int r = 0; r < 20; ++r) {
    for (const Route& route : town.routes) {
      RouteTracker tracker(route);
      for (double s = 0.5; s < route.length_m(); s += 0.5, ++updates)
        tracker.update(route.pose_at(s));
    }
  }
  const double track_s = seconds_since(start) / updates;
  std::printf(
      "locate(point, yaw): %.2f us/query (%.0f%% found); is_drivable: %.2f us/query; "
      "RouteTracker::update: %.2f us\n",
      1e6 * locate_s, 100.0 * found / (rounds * poses.size()), 1e6 * drivable_s, 1e6 * track_s);
  std::printf(
      "per env step (locate + is_drivable + tracker): %.2f us, %.2f%% of a 500 us "
      "budget (2000 steps/s)\n",
      1e6 * (locate_s + drivable_s + track_s), 100.0 * (locate_s + drivable_s + track_s) / 500e-6);
  (void)drivable;
  return 0;
}
