// The env::Env -> agent::Environment adapter on town01 with a 32 x 32 camera: frames, rewards,
// episode ends, density periods and the result observer.
#include "indrive/actor/env_adapter.h"

#include <gtest/gtest.h>

#include <map>
#include <random>
#include <set>

#include "indrive/agent/observation.h"
#include "indrive/envserver/scene.h"
#include "testing.h"

namespace indrive::actor {
namespace {

env::EnvConfig small_env(const std::string& task) {
  env::EnvConfig config;
  config.town = "town01";
  config.camera.width = 32;
  config.camera.height = 32;
  config.events.time_limit_steps = 40;
  config.task = task;
  return config;
}

// The adapter hands camera frames (class ids) to the agent, which colours them itself: both
// palettes must be the same.
TEST(EnvAdapterTest, TheAgentsPaletteEqualsTheCameras) {
  ASSERT_EQ(agent::kNumClasses, env::kNumSemanticClasses);
  for (int c = 0; c < agent::kNumClasses; ++c) {
    for (int k = 0; k < 3; ++k) EXPECT_EQ(agent::kPaletteRgb[c][k], env::kPaletteRgb[c][k]) << c;
  }
}

TEST(EnvConfigTest, ThePresetSizesTheCameraAndTaskPhasesSetTheTask) {
  testing::TempDir dir;
  const auto pretrain =
      service::ServiceConfig::resolve({.run_dir = dir.path() / "r", .overrides = {"preset=tiny"}});
  const env::EnvConfig env = env_config(pretrain);
  EXPECT_EQ(env.camera.width, 32) << "the camera renders the preset's image size";
  EXPECT_TRUE(env.task.empty()) << "pretraining computes no reward";
  // The environment of another agent config renders that config's image size.
  EXPECT_EQ(env_config(pretrain, agent::preset("small")).camera.width, 128);

  const auto task = service::ServiceConfig::resolve(
      {.run_dir = dir.path() / "r",
       .overrides = {"agent.phase=finetune", "agent.task=collision_avoidance"}});
  EXPECT_EQ(env_config(task).task, "collision_avoidance");

  EXPECT_EQ(env_config(pretrain).town_options.route_set, "right") << "the default route set";
  const auto left = service::ServiceConfig::resolve(
      {.run_dir = dir.path() / "l", .overrides = {"env.route_set=left"}});
  EXPECT_EQ(env_config(left).town_options.route_set, "left");
  EXPECT_THROW(service::ServiceConfig::resolve(
                   {.run_dir = dir.path() / "m", .overrides = {"env.route_set=middle"}}),
               std::exception)
      << "only the shipped route sets";
}

// Every shipped config gives an environment, so a renamed env key cannot break a recipe.
TEST(EnvConfigTest, EveryShippedConfigGivesAnEnvironment) {
  testing::TempDir dir;
  const auto files = testing::shipped_configs();
  EXPECT_GE(files.size(), 8u);
  for (const auto& file : files) {
    SCOPED_TRACE(file.filename().string());
    const auto config =
        service::ServiceConfig::resolve({.config_file = file, .run_dir = dir.path() / "r"});
    EXPECT_FALSE(env_config(config).town.empty());
  }
}

TEST(EnvAdapterTest, FramesRewardsAndEpisodeEndsOfAPretrainingEnv) {
  env::Env env(small_env(""));
  EnvAdapter adapter(env, {.densities = {0, 5}, .density_period_steps = 50, .seed = 3});
  int observed = 0;
  adapter.on_result([&](const env::StepResult&) { ++observed; });
  std::set<int> densities;
  int episodes = 0;
  agent::EnvStep step = adapter.reset();
  densities.insert(adapter.density());
  for (int i = 0; i < 300; ++i) {
    ASSERT_EQ(step.frame.size(), 32u * 32u);
    for (const std::uint8_t id : step.frame) ASSERT_LT(id, 8) << "not a class id";
    EXPECT_EQ(step.reward, 0.0f) << "pretraining has no reward";
    EXPECT_EQ(step.is_last, adapter.last().is_last);
    EXPECT_EQ(step.is_terminal, adapter.last().is_terminal);
    if (step.is_last) {
      ++episodes;
      step = adapter.reset();
      densities.insert(adapter.density());
    } else {
      step = adapter.step(4);  // straight ahead, moderate throttle
    }
  }
  EXPECT_EQ(observed, adapter.frames());
  EXPECT_EQ(adapter.frames(), 301);
  // Episodes end within the 40-step limit, and the density is redrawn across periods.
  EXPECT_GE(episodes, 300 / 41);
  EXPECT_EQ(densities, (std::set<int>{0, 5}));
}

TEST(EnvAdapterTest, TaskPhaseCarriesTheEnvReward) {
  env::Env env(small_env("lane_following"));
  EnvAdapter adapter(env, {.route = "straight", .densities = {0}, .seed = 1});
  agent::EnvStep step = adapter.reset();
  double total = 0.0;
  for (int i = 0; i < 20 && !step.is_last; ++i) {
    step = adapter.step(4);
    ASSERT_TRUE(adapter.last().reward.has_value());
    EXPECT_FLOAT_EQ(step.reward, static_cast<float>(*adapter.last().reward));
    total += step.reward;
  }
  EXPECT_NE(total, 0.0);
}

// Each finished episode reaches on_episode once, after its last result, with the town, the
// route drawn for it and the sum of its rewards.
TEST(EnvAdapterTest, EachFinishedEpisodeIsRecordedWithItsRouteAndReturn) {
  env::Env env(small_env("lane_following"));
  EnvAdapter adapter(env,
                     {.town = "town01", .route = "straight,two_turn", .densities = {0}, .seed = 2});
  std::vector<EpisodeRecord> records;
  adapter.on_episode([&](const EpisodeRecord& record) { records.push_back(record); });
  double total = 0.0;
  std::vector<double> returns;
  std::vector<std::string> routes;
  agent::EnvStep step = adapter.reset();
  routes.push_back(env.route()->name());
  for (int i = 0; i < 200; ++i) {
    if (step.is_last) {
      returns.push_back(total);
      total = 0.0;
      step = adapter.reset();
      routes.push_back(env.route()->name());
    } else {
      step = adapter.step(i % 3 == 0 ? 1 : 4);
      total += step.reward;
    }
  }
  ASSERT_GE(records.size(), 3u);  // the 40-step limit ends them
  ASSERT_EQ(records.size(), returns.size());
  for (std::size_t i = 0; i < records.size(); ++i) {
    EXPECT_EQ(records[i].eval_kind, "training");
    EXPECT_EQ(records[i].town, "town01");
    EXPECT_EQ(records[i].route, routes[i]);
    EXPECT_NEAR(records[i].episode_return, returns[i], 1e-3);
    EXPECT_GT(records[i].steps, 0);
    EXPECT_LE(records[i].steps, 40);
    EXPECT_FALSE(records[i].success);
    EXPECT_FALSE(records[i].failure_reason.empty());
  }
}

TEST(EnvAdapterTest, RejectsUnusableOptions) {
  env::Env env(small_env(""));
  EXPECT_THROW(EnvAdapter(env, {.densities = {}}), std::invalid_argument);
  EXPECT_THROW(EnvAdapter(env, {.density_period_steps = 0}), std::invalid_argument);
  EXPECT_THROW(EnvAdapter(env, {.route = "straight,,two_turn"}), std::invalid_argument);
}

TEST(EnvAdapterTest, ARouteListIsReadAndEveryRouteIsDrawn) {
  EXPECT_TRUE(route_list("").empty());
  EXPECT_EQ(route_list("straight"), std::vector<std::string>{"straight"});
  EXPECT_EQ(route_list(" straight, two_turn "), (std::vector<std::string>{"straight", "two_turn"}));
  // One route never consumes the generator, so a one-route run keeps its seeds.
  std::mt19937_64 rng(3), same(3);
  EXPECT_EQ(draw_route({"straight"}, rng), "straight");
  EXPECT_EQ(rng(), same());
  // Several: each is drawn, and the episodes of a task run follow them.
  const std::vector<std::string> routes = route_list("straight,right_loop,left_loop,two_turn");
  std::map<std::string, int> drawn;
  for (int i = 0; i < 200; ++i) ++drawn[draw_route(routes, rng)];
  for (const std::string& r : routes) EXPECT_GT(drawn[r], 20) << r;
  env::Env env(small_env("lane_following"));
  EnvAdapter adapter(env, {.route = "straight,two_turn", .densities = {0}, .seed = 2});
  std::map<std::string, int> episodes;
  for (int i = 0; i < 8; ++i) {
    adapter.reset();
    ASSERT_NE(env.route(), nullptr);
    ++episodes[env.route()->name()];
  }
  EXPECT_EQ(episodes.size(), 2u);
}

}  // namespace
}  // namespace indrive::actor
