// Feasibility: every route of both built-in towns can be driven end to end by the scripted
// follower with the 9 actions only, at 3 and 5 m/s, without any failure event (no traffic).
#include "indrive/envserver/follower.h"

#include <gtest/gtest.h>

#include "indrive/envserver/env.h"

namespace indrive::env {
namespace {

struct Case {
  std::string town;
  std::string route;
  double speed_mps;
};

// Readable parameter in test output.
void PrintTo(const Case& c, std::ostream* os) {
  *os << c.town << "/" << c.route << " at " << c.speed_mps << " m/s";
}

std::string case_name(const ::testing::TestParamInfo<Case>& info) {
  return info.param.town + "_" + info.param.route + "_" +
         std::to_string(static_cast<int>(info.param.speed_mps)) + "mps";
}

std::vector<Case> all_cases() {
  std::vector<Case> cases;
  for (const char* town : {"town01", "town02"}) {
    for (std::string_view route : kRouteNames) {
      for (double speed : {3.0, 5.0}) cases.push_back({town, std::string(route), speed});
    }
  }
  return cases;
}

// One Env per town (libtraci: several simulations in one process).
std::map<std::string, std::unique_ptr<Env>>& all_envs() {
  static std::map<std::string, std::unique_ptr<Env>> envs;
  return envs;
}

Env& env_for(const std::string& town) {
  auto& env = all_envs()[town];
  if (!env) {
    EnvConfig config;
    config.town = town;
    config.sumo.mode = SumoMode::kLibtraci;
    config.camera.width = 32;
    config.camera.height = 32;
    // Feasibility of the driving, not of the episode budget: a slow lap may exceed 1000 steps.
    config.events.time_limit_steps = 100000;
    env = std::make_unique<Env>(config);
  }
  return *env;
}

class Feasibility : public ::testing::TestWithParam<Case> {
 protected:
  // Closes the simulations one after another inside the test run, where a failure shows up as
  // a test error, rather than in static destruction after main.
  static void TearDownTestSuite() { all_envs().clear(); }
};

TEST_P(Feasibility, FollowerCompletesTheRouteWithoutFailure) {
  const Case& c = GetParam();
  Env& env = env_for(c.town);
  StepResult r = env.reset({.route = c.route, .density = 0});
  WaypointFollower follower(*env.route(), env.config().ego, {.target_speed_mps = c.speed_mps});
  follower.reset();
  double speed_sum = 0.0;
  double worst_lateral = 0.0;
  while (!r.is_last) {
    r = env.step(follower.act(env.ego()));
    speed_sum += r.ego.speed_mps;
    if (!env.events().road().in_junction) {
      worst_lateral = std::max(worst_lateral, std::abs(env.events().road().lateral_m));
    }
  }
  EXPECT_EQ(r.events, kDestination)
      << event_names(r.events) << " at step " << r.step << ", progress " << r.route_progress_m
      << " of " << env.route()->length_m() << " m";
  const double mean_speed = speed_sum / r.step;
  RecordProperty("steps", r.step);
  RecordProperty("worst_lateral_cm", static_cast<int>(100 * worst_lateral));
  // The speed is held near the target once up to speed (the start from rest lowers the mean).
  EXPECT_GT(mean_speed, 0.75 * c.speed_mps);
  EXPECT_LT(mean_speed, 1.1 * c.speed_mps);
}

INSTANTIATE_TEST_SUITE_P(AllRoutes, Feasibility, ::testing::ValuesIn(all_cases()), case_name);

}  // namespace
}  // namespace indrive::env
