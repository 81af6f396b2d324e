// Tests of protocol_episode.h: one protocol episode, as the evaluator and the local trainer's
// evaluation both run it.
#include "indrive/actor/protocol_episode.h"

#include <gtest/gtest.h>

#include <filesystem>

#include "indrive/actor/episode_video.h"
#include "indrive/actor/protocol_record.h"
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
