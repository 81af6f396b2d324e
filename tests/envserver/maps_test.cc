// Public OpenDRIVE maps (CARLA's Town04, Town06, Town07 and Town10HD, tests/data/maps/) through
// the whole path a user's map takes: conversion, derived routes checked by the scripted
// follower, and the follower driving every route offered in SUMO without traffic. Each map
// loads or is refused with a named reason, and no process aborts (SUMO runs in this process).
#include <gtest/gtest.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <optional>

#include "indrive/basics/stopwatch.h"
#include "indrive/envserver/env.h"
#include "indrive/envserver/follower.h"
#include "indrive/envserver/route_check.h"
#include "indrive/envserver/town.h"
#include "testing.h"

namespace indrive::env {
namespace {

namespace fs = std::filesystem;

TEST(Maps, EachPublicMapLoadsOrIsRefusedByNameAndTheFollowerDrivesEveryRouteOffered) {
  testing::TempDir dir("indrive-maps");
  EnvConfig config;
  config.town = "town01";
  config.town_options.cache_dir = dir.path() / "cache";  // every map converted and checked anew
  config.camera.width = 32;
  config.camera.height = 32;
  config.events.time_limit_steps = 100000;  // the check already held each route to its budget
  Env env(config);
  int loaded = 0, refused = 0;
  for (const auto& entry :
       fs::directory_iterator(fs::path(INDRIVE_SOURCE_DIR) / "tests" / "data" / "maps")) {
    if (entry.path().extension() != ".gz") continue;
    const fs::path map = dir.path() / entry.path().stem();  // <name>.xodr
    const std::string unpack = "gzip -dc '" + entry.path().string() + "' > '" + map.string() + "'";
    ASSERT_EQ(std::system(unpack.c_str()), 0) << unpack;
    const std::string name = map.stem().string();

    const auto start = std::chrono::steady_clock::now();
    std::optional<Town> loaded_town;
    try {
      loaded_town.emplace(load_town(map.string(), config.town_options));
    } catch (const RouteError& error) {
      // Refused: the message names the map and the route kinds it cannot offer.
      const std::string what = error.what();
      EXPECT_NE(what.find(name), std::string::npos) << what;
      EXPECT_NE(what.find("route"), std::string::npos) << what;
      std::printf("%s: refused: %s\n", name.c_str(), what.c_str());
      ++refused;
      continue;
    }
    const double first_s = seconds_since(start);
    const Town& town = *loaded_town;
    const auto cached_start = std::chrono::steady_clock::now();
    load_town(map.string(), config.town_options);
    const double cached_s = seconds_since(cached_start);
    // What the check adds to the first load: deriving with it against deriving without.
    const auto plain_start = std::chrono::steady_clock::now();
    derive_routes(town.net);
    const double plain_s = seconds_since(plain_start);
    const auto checked_start = std::chrono::steady_clock::now();
    derive_routes(town.net,
                  [&](const RouteSpec& spec) { return oracle_drive_failure(town.net, spec); });
    const double checked_s = seconds_since(checked_start);
    std::printf(
        "%s: %zu routes, %zu candidates dropped; first load %.2f s, cached %.2f s; "
        "derivation %.3f s unchecked, %.3f s checked\n",
        name.c_str(), town.routes.size(), town.dropped_routes.size(), first_s, cached_s, plain_s,
        checked_s);
    ++loaded;

    for (const Route& route : town.routes) {
      StepResult r = env.reset({.town = map.string(), .route = route.name(), .density = 0});
      WaypointFollower follower(*env.route(), config.ego);
      follower.reset();
      while (!r.is_last) r = env.step(follower.act(env.ego()));
      EXPECT_TRUE((r.events & kDestination) != 0 && (r.events & kFailureEvents) == 0)
          << name << " " << route.name() << ": " << event_names(r.events) << " at step " << r.step;
    }
  }
  EXPECT_GE(loaded, 2) << "the maps that loaded before the check must still load";
  EXPECT_EQ(loaded + refused, 4);
}

}  // namespace
}  // namespace indrive::env
