// Tests of eval_protocol_episode.h: one protocol episode, as the evaluator and the local trainer's
// evaluation both run it.
#include "indrive/actor/eval_protocol_episode.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <memory>

#include "indrive/actor/episode_video.h"
#include "indrive/actor/eval_protocol_record.h"
#include "indrive/envserver/events.h"
#include "testing.h"

namespace indrive::actor {
namespace {

env::EnvConfig small_protocol_env() {
  env::EnvConfig config;
  config.town = "town01";
  config.camera.width = 32;
  config.camera.height = 32;
  return protocol_env_config(config);
}

EpisodeSpec straight_episode(int episode) {
  const ProtocolGrid grid{.towns = {"town01"},
                          .routes = {"straight"},
                          .densities = {5},
                          .episodes_per_cell = episode + 1};
  return grid.all_episodes().at(static_cast<std::size_t>(episode));
}

TEST(ProtocolEpisode, TheOracleReachesTheDestinationTheSameWayTwice) {
  env::Env env(small_protocol_env());
  auto oracle = make_oracle_policy({});
  const std::atomic<bool> stop{false};
  const EpisodeSpec spec = straight_episode(0);
  const EpisodeOutcome first = run_protocol_episode(env, *oracle, spec, {}, stop);
  ASSERT_FALSE(first.stopped);
  const EpisodeRecord record = protocol_record(spec, first);
  EXPECT_TRUE(record.success) << record.failure_reason;
  EXPECT_DOUBLE_EQ(first.route_completion, 1.0);
  EXPECT_TRUE(first.events & env::kDestination);
  EXPECT_LT(first.steps, route_step_budget(env.route()->length_m()));

  const EpisodeOutcome again = run_protocol_episode(env, *oracle, spec, {}, stop);
  EXPECT_EQ(again.steps, first.steps);
  EXPECT_EQ(again.events, first.events);
  EXPECT_DOUBLE_EQ(again.episode_return, first.episode_return);
}

TEST(ProtocolEpisode, TheBudgetEndsAnEpisodeAsATimeLimitAndAStopDiscardsIt) {
  env::Env env(small_protocol_env());
  const std::atomic<bool> go{false};
  const EpisodeSpec spec = straight_episode(1);
  // A budget speed far above what a car reaches leaves a few steps: the protocol's time limit.
  auto oracle = make_oracle_policy({});
  const ProtocolEpisodeOptions short_budget{.budget_speed_mps = 1000.0, .budget_slack = 1.0};
  const EpisodeOutcome cut = run_protocol_episode(env, *oracle, spec, short_budget, go);
  ASSERT_FALSE(cut.stopped);
  EXPECT_TRUE(cut.events & env::kTimeLimit);
  EXPECT_FALSE(protocol_record(spec, cut).success);
  EXPECT_GT(cut.route_completion, 0.0);
  EXPECT_LT(cut.route_completion, 1.0);

  const std::atomic<bool> stop{true};
  EXPECT_TRUE(run_protocol_episode(env, *oracle, spec, {}, stop).stopped);
}

// The oracle drives every route of both CARLA towns to its end under both protocols (one
// episode each, traffic density 5); the results page has the full figures.
TEST(ProtocolEpisode, TheOracleCompletesEveryCarlaRouteUnderBothProtocols) {
  for (const EvalProtocol protocol : {EvalProtocol::kStrict, EvalProtocol::kIndriveCode}) {
    for (const std::string town : {"carla_town01", "carla_town02"}) {
      env::EnvConfig config;
      config.town = town;
      config.camera.width = 32;
      config.camera.height = 32;
      env::Env env(protocol_env_config(config, protocol));
      auto oracle = make_oracle_policy({});
      const std::atomic<bool> go{false};
      ProtocolGrid grid{.towns = {town}, .densities = {5}, .episodes_per_cell = 1};
      set_grid_routes(grid, "all");
      const ProtocolEpisodeOptions options{.protocol = protocol};
      for (const EpisodeSpec& spec : grid.all_episodes()) {
        const EpisodeOutcome outcome = run_protocol_episode(env, *oracle, spec, options, go);
        const EpisodeRecord record = protocol_record(spec, outcome);
        EXPECT_TRUE(record.success)
            << protocol_name(protocol) << " " << town << " " << spec.route << ": "
            << record.failure_reason << " after " << record.steps << " steps";
        EXPECT_EQ(record.protocol, protocol_name(protocol));
        EXPECT_EQ(record.lane_invasions, 0) << town << " " << spec.route;
      }
    }
  }
}

// Under indrive_code nothing but the code's rules end an episode: random actions on a CARLA
// route end by a failure or the budget, never by success.
TEST(ProtocolEpisode, IndriveCodeEpisodesEndByTheCodesRulesOrItsBudget) {
  env::EnvConfig config;
  config.town = "carla_town02";
  config.camera.width = 32;
  config.camera.height = 32;
  auto env = std::make_unique<env::Env>(protocol_env_config(config, EvalProtocol::kIndriveCode));
  auto random = make_random_policy(5);
  const std::atomic<bool> go{false};
  ProtocolGrid grid{.towns = {"carla_town02"},
                    .routes = {"straight_1"},
                    .densities = {5},
                    .episodes_per_cell = 3};
  const ProtocolEpisodeOptions options{.protocol = EvalProtocol::kIndriveCode,
                                       .code_budget_steps = 3000};
  const std::uint32_t code_failures = env::kCollision | env::kOutOfLane | env::kOffRoad |
                                      env::kWrongDirection | env::kTooSlow | env::kTimeLimit;
  for (const EpisodeSpec& spec : grid.all_episodes()) {
    const EpisodeOutcome outcome = run_protocol_episode(*env, *random, spec, options, go);
    const EpisodeRecord record = protocol_record(spec, outcome);
    EXPECT_FALSE(record.success);
    EXPECT_NE(outcome.events & code_failures, 0u) << env::event_names(outcome.events);
    EXPECT_EQ(outcome.events & (env::kLaneInvasion | env::kOffRoute | env::kStall), 0u)
        << env::event_names(outcome.events);
    EXPECT_LE(outcome.steps, 3000);
  }
  // An env built for the other protocol is refused (libsumo: one simulation per process).
  env.reset();
  env::Env strict_env(small_protocol_env());
  EXPECT_DEATH(run_protocol_episode(strict_env, *random, straight_episode(0), options, go),
               "event rules");
}

TEST(ProtocolEpisode, TheFirstEpisodesOfACellAreRecorded) {
  testing::TempDir dir;
  env::Env env(small_protocol_env());
  auto random = make_random_policy(3);
  const std::atomic<bool> go{false};
  const ProtocolEpisodeOptions options{.video_episodes = 1, .video_dir = dir.path() / "videos"};
  const EpisodeSpec first = straight_episode(0);
  const EpisodeSpec second = straight_episode(1);
  ASSERT_FALSE(run_protocol_episode(env, *random, first, options, go).stopped);
  ASSERT_FALSE(run_protocol_episode(env, *random, second, options, go).stopped);
  EXPECT_TRUE(std::filesystem::exists(episode_video_path(options.video_dir, first)));
  EXPECT_FALSE(std::filesystem::exists(episode_video_path(options.video_dir, second)));
}

}  // namespace
}  // namespace indrive::actor
