#include "indrive/envserver/env.h"

#include <gtest/gtest.h>
#include <signal.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>
#include <vector>

#include "indrive/basics/checksum.h"
#include "indrive/envserver/follower.h"
#include "testing.h"

namespace indrive::env {
namespace {

// libsumo runs one simulation per process, so all tests here share one Env (64x64 keeps the
// rendering cheap; the camera has its own tests).
Env& shared_env() {
  static std::unique_ptr<Env> env = [] {
    EnvConfig config;
    config.town = "town01";
    config.camera.width = 64;
    config.camera.height = 64;
    return std::make_unique<Env>(config);
  }();
  return *env;
}

// The SUMO processes whose command line holds `tag` (libtraci starts SUMO in the background,
// so it is no descendant of this process; the tag tells it from other tests' SUMOs).
std::vector<pid_t> sumo_processes(const std::string& tag) {
  namespace fs = std::filesystem;
  std::vector<pid_t> found;
  std::error_code error;
  for (const auto& entry : fs::directory_iterator("/proc", error)) {
    const std::string name = entry.path().filename().string();
    if (name.empty() || name.find_first_not_of("0123456789") != std::string::npos) continue;
    std::ifstream in(entry.path() / "cmdline");
    const std::string cmdline((std::istreambuf_iterator<char>(in)), {});
    if (cmdline.find("sumo") != std::string::npos && cmdline.find(tag) != std::string::npos) {
      found.push_back(std::stoi(name));
    }
  }
  return found;
}

std::uint32_t crc_of(const cv::Mat& image) {
  EXPECT_TRUE(image.isContinuous());
  return indrive::crc32(image.data, image.total() * image.elemSize());
}

TEST(Env, SameSeedsGiveBitwiseEqualObservationsFor500Steps) {
  Env& env = shared_env();
  // Without a time limit or road rules ending it early: the follower keeps the ego on a loop.
  ResetOptions options{.route = "right_loop", .density = 20, .traffic_seed = 11, .spawn_seed = 3};
  auto drive = [&](const ResetOptions& o) {
    std::vector<std::uint32_t> crcs;
    StepResult r = env.reset(o);
    WaypointFollower follower(*env.route(), env.config().ego, {.target_speed_mps = 5.0});
    follower.reset();
    crcs.push_back(crc_of(r.observation));
    for (int i = 0; i < 500 && !r.is_last; ++i) {
      r = env.step(follower.act(env.ego()));
      crcs.push_back(crc_of(r.observation));
    }
    return crcs;
  };
  const auto first = drive(options);
  const auto second = drive(options);
  ASSERT_EQ(first.size(), 501u) << "the episode ended early";
  EXPECT_EQ(first, second);
  // Another traffic seed changes what the camera sees (traffic is really in the picture).
  options.traffic_seed = 12;
  const auto other = drive(options);
  EXPECT_NE(first, other);
}

TEST(Env, RandomSpawnDependsOnTheSpawnSeedOnly) {
  Env& env = shared_env();
  const Pose2 a = env.reset({.density = 0, .traffic_seed = 1, .spawn_seed = 5}).ego.pose;
  const Pose2 b = env.reset({.density = 0, .traffic_seed = 2, .spawn_seed = 5}).ego.pose;
  const Pose2 c = env.reset({.density = 0, .traffic_seed = 1, .spawn_seed = 6}).ego.pose;
  EXPECT_EQ(a.x_m, b.x_m);
  EXPECT_EQ(a.y_m, b.y_m);
  EXPECT_TRUE(a.x_m != c.x_m || a.y_m != c.y_m);
}

TEST(Env, TrafficIsKeptAtTheConfiguredDensity) {
  Env& env = shared_env();
  for (int density : {5, 10, 20}) {
    StepResult r = env.reset({.route = "right_loop", .density = density, .traffic_seed = 4});
    WaypointFollower follower(*env.route(), env.config().ego, {.target_speed_mps = 5.0});
    follower.reset();
    int max_near = 0;
    double sum_near = 0.0;
    int samples = 0;
    for (int i = 0; i < 300 && !r.is_last; ++i) {
      r = env.step(follower.act(env.ego()));
      if (i < 50) continue;  // insertion takes a few steps
      int near = 0;
      for (const Box& b : env.traffic_boxes()) {
        if (std::hypot(b.pose.x_m - r.ego.pose.x_m, b.pose.y_m - r.ego.pose.y_m) <= 150.0) ++near;
      }
      max_near = std::max(max_near, near);
      sum_near += near;
      ++samples;
    }
    ASSERT_GT(samples, 100) << "episode ended early: " << event_names(r.events);
    // Vehicles leaving the radius are replaced within a few steps (insertion delay, a few spawns
    // per step), so the count dips briefly; on average it holds.
    EXPECT_NEAR(sum_near / samples, density, 1.0) << "density " << density;
    EXPECT_LE(max_near, density + 2) << "density " << density;
  }
}

TEST(Env, StandingStillStallsAfterSixtySeconds) {
  Env& env = shared_env();
  StepResult r = env.reset({.route = "straight", .density = 0});
  const int no_throttle_straight = encode_action(1, 0);
  while (!r.is_last) r = env.step(no_throttle_straight);
  EXPECT_EQ(r.events, kStall);
  EXPECT_EQ(r.step, 600);
  EXPECT_TRUE(r.is_terminal);
}

TEST(Env, CirclingLeftLeavesTheLane) {
  Env& env = shared_env();
  StepResult r = env.reset({.route = "straight", .density = 0});
  while (!r.is_last) r = env.step(encode_action(0, 2));
  EXPECT_TRUE(r.events & (kLaneInvasion | kOffRoad | kWrongDirection)) << event_names(r.events);
  EXPECT_FALSE(r.events & kCollision);
  EXPECT_LT(r.step, 100);
}

TEST(Env, TakingATurnTheRouteDoesNotTakeEndsTheEpisodeAsOffRoute) {
  Env& env = shared_env();
  // left_loop runs south on N1_M2, M2_M1 and turns left at M1; the follower drives a route
  // that goes straight on there, to M1_B1.
  StepResult r = env.reset({.route = "left_loop", .density = 0});
  const Route wrong(env.town().net, RouteSpec{"wrong", false, {"N1_M2", "M2_M1", "M1_B1"}});
  WaypointFollower follower(wrong, env.config().ego, {.target_speed_mps = 5.0});
  follower.reset();
  while (!r.is_last) r = env.step(follower.act(env.ego()));
  EXPECT_EQ(r.events, kOffRoute) << event_names(r.events);
  EXPECT_EQ(event_names(r.events), "off_route");
  EXPECT_TRUE(r.is_terminal);
  const RoadStatus& road = env.events().road();
  ASSERT_GE(road.lane, 0);
  EXPECT_EQ(env.town().net.edge(env.town().net.lane(road.lane).edge).id, "M1_B1");
}

TEST(Env, RewardOnlyInTaskPhases) {
  Env& env = shared_env();
  StepResult r = env.reset({.route = "straight", .density = 0});
  EXPECT_FALSE(r.reward.has_value());
  r = env.step(encode_action(1, 2));
  EXPECT_FALSE(r.reward.has_value());  // pretraining config: no reward at all
  EXPECT_TRUE(r.is_first == false);
}

TEST(Env, TaskPhaseRewardsProgressAlongTheRoute) {
  EnvConfig config;
  config.town = "town02";
  config.task = "lane_following";
  config.sumo.mode = SumoMode::kLibtraci;  // the shared Env holds libsumo
  config.camera.width = 32;
  config.camera.height = 32;
  Env env(config);
  StepResult r = env.reset({.route = "straight", .density = 0});
  EXPECT_FALSE(r.reward.has_value());  // no reward for the reset observation
  WaypointFollower follower(*env.route(), config.ego, {.target_speed_mps = 5.0});
  follower.reset();
  double waypoint_sum = 0.0;
  for (int i = 0; i < 200 && !r.is_last; ++i) {
    r = env.step(follower.act(env.ego()));
    ASSERT_TRUE(r.reward.has_value());
    EXPECT_DOUBLE_EQ(*r.reward, r.reward_terms.total());
    EXPECT_DOUBLE_EQ(r.reward_terms.time, -0.01);
    waypoint_sum += r.reward_terms.waypoint;
  }
  // Waypoints are ~2 m apart: the reward counts about one per 2 m of progress.
  EXPECT_NEAR(waypoint_sum, r.route_progress_m / 2.0, 3.0);
  // At the target speed, straight along the lane, the speed term is near its best (0.05 * 5).
  EXPECT_GT(r.reward_terms.speed, 0.2);
}

TEST(Env, ResetCanSwitchTowns) {
  Env& env = shared_env();
  env.reset({.town = "town02", .route = "left_loop", .density = 5});
  EXPECT_EQ(env.town().name, "town02");
  EXPECT_EQ(env.route()->name(), "left_loop");
  StepResult r = env.step(encode_action(1, 1));
  EXPECT_EQ(r.step, 1);
  env.reset({.town = "town01", .route = "straight", .density = 0});
  EXPECT_EQ(env.town().name, "town01");
}

TEST(Env, BadInputIsNamed) {
  Env& env = shared_env();
  try {
    env.reset({.density = 7});
    FAIL() << "expected EnvError";
  } catch (const EnvError& e) {
    EXPECT_NE(std::string(e.what()).find("7"), std::string::npos);
  }
  try {
    env.reset({.route = "figure_eight"});
    FAIL() << "expected RouteError";
  } catch (const RouteError& e) {
    EXPECT_NE(std::string(e.what()).find("figure_eight"), std::string::npos);
    EXPECT_NE(std::string(e.what()).find("right_loop"), std::string::npos);
  }
  EnvConfig missing;
  missing.town = "/nonexistent/town.net.xml";
  missing.sumo.mode = SumoMode::kLibtraci;  // the shared Env holds libsumo
  EXPECT_THROW(Env{missing}, MapError);
  EnvConfig no_sumo;
  no_sumo.sumo.mode = SumoMode::kLibtraci;
  no_sumo.sumo.sumo_binary = "/nonexistent/sumo";
  try {
    Env env2(no_sumo);
    FAIL() << "expected SumoError";
  } catch (const SumoError& e) {
    EXPECT_NE(std::string(e.what()).find("/nonexistent/sumo"), std::string::npos);
  }
  // The env still works after the failed resets.
  EXPECT_NO_THROW(env.reset({.route = "straight", .density = 5}));
}

// SUMO dying mid-episode (here killed; on a user's map, SUMO's own assertion) ends that
// episode as env_fault, not as a failure of the policy; the next episode runs on a new SUMO.
// libtraci, where SUMO is a child process, is the mode in which a SUMO abort can be survived.
TEST(Env, ASumoThatDiesMidEpisodeEndsItAsEnvFaultAndTheNextEpisodeRuns) {
  EnvConfig config;
  config.town = "town02";
  config.sumo.mode = SumoMode::kLibtraci;  // the shared Env holds libsumo
  config.camera.width = 32;
  config.camera.height = 32;
  const std::string tag = "envfault" + std::to_string(::getpid());
  config.sumo.extra_args = {"--output-prefix", tag};  // names this test's SUMO; writes nothing
  Env env(config);
  StepResult r = env.reset({.route = "straight", .density = 5, .traffic_seed = 3});
  WaypointFollower follower(*env.route(), config.ego, {.target_speed_mps = 5.0});
  follower.reset();
  for (int i = 0; i < 20; ++i) ASSERT_FALSE(env.step(follower.act(env.ego())).is_last);
  const auto sumo = sumo_processes(tag);
  ASSERT_EQ(sumo.size(), 1u) << "expected one SUMO process with " << tag << " in its arguments";
  ASSERT_EQ(::kill(sumo[0], SIGKILL), 0);
  r = env.step(follower.act(env.ego()));
  EXPECT_TRUE(r.is_last);
  EXPECT_FALSE(r.is_terminal);
  EXPECT_EQ(r.events, kEnvFault);
  EXPECT_EQ(r.step, 21);
  EXPECT_EQ(env.env_faults(), 1);

  // The next episode runs on a new SUMO, the same as a fresh Env's.
  r = env.reset({.route = "straight", .density = 5, .traffic_seed = 3});
  follower.reset();
  int steps = 0;
  for (; steps < 60 && !r.is_last; ++steps) r = env.step(follower.act(env.ego()));
  EXPECT_EQ(steps, 60) << event_names(r.events);
  EXPECT_EQ(env.traffic_count(), 5);
  EXPECT_EQ(env.env_faults(), 1);

  // A SUMO that died between episodes is restarted by the reset.
  for (pid_t pid : sumo_processes(tag)) ::kill(pid, SIGKILL);
  r = env.reset({.route = "straight", .density = 5, .traffic_seed = 3});
  EXPECT_EQ(env.env_faults(), 2);
  EXPECT_FALSE(env.step(follower.act(env.ego())).is_last);
}

}  // namespace
}  // namespace indrive::env
