// Tests of eval_protocol_record.h: grid names, the step budget, route completion and the verdict.
#include "indrive/actor/eval_protocol_record.h"

#include <gtest/gtest.h>

#include <cstring>
#include <fstream>
#include <numbers>

#include "eval_test_support.h"
#include "indrive/actor/policies.h"
#include "indrive/actor/snapshot_file.h"
#include "indrive/agent/agent.h"
#include "indrive/agent/policy.h"
#include "indrive/basics/checksum.h"
#include "indrive/envserver/town.h"
#include "indrive/nn/serialize.h"
#include "testing.h"

namespace indrive::actor {
namespace {

using test_support::eval_error_of;
using test_support::tiny_snapshot;

TEST(ProtocolRecord, UnknownTownOrRouteNamesTheValueAndWhatExists) {
  ProtocolGrid grid{.towns = {"town01", "town99"}, .routes = {"straight"}};
  std::string message = eval_error_of([&] { check_grid_names(grid); });
  EXPECT_NE(message.find("'town99'"), std::string::npos) << message;
  EXPECT_NE(message.find("town01, town02"), std::string::npos) << message;

  grid = {.towns = {"town02"}, .routes = {"straight", "figure_eight"}};
  message = eval_error_of([&] { check_grid_names(grid); });
  EXPECT_NE(message.find("'figure_eight'"), std::string::npos) << message;
  EXPECT_NE(message.find("straight, right_loop, left_loop, two_turn"), std::string::npos)
      << message;

  grid = {.towns = {"town01", "town02", "grid:3"}};
  EXPECT_NO_THROW(check_grid_names(grid));

  // Our four route names are no routes of the CARLA towns; "all" gives each town its own.
  grid = {.towns = {"town01", "carla_town01"}};
  message = eval_error_of([&] { check_grid_names(grid); });
  EXPECT_NE(message.find("'straight' on carla_town01"), std::string::npos) << message;
  EXPECT_NE(message.find("straight_1, straight_2, right_1"), std::string::npos) << message;
  set_grid_routes(grid, "all");
  EXPECT_NO_THROW(check_grid_names(grid));
  EXPECT_EQ(grid.routes_of("town01"),
            (std::vector<std::string>{"straight", "right_loop", "left_loop", "two_turn"}));
  EXPECT_EQ(grid.routes_of("carla_town01").size(), 6u);
  set_grid_routes(grid, "straight, right_loop");
  EXPECT_EQ(grid.routes, (std::vector<std::string>{"straight", "right_loop"}));
  EXPECT_TRUE(grid.town_routes.empty());
}

TEST(ProtocolRecord, StepBudgetIsFiveStepsPerMetreByDefault) {
  EXPECT_EQ(route_step_budget(649.0), 3245);  // town01's longest loop
  EXPECT_EQ(route_step_budget(200.0), 1000);
  EXPECT_EQ(route_step_budget(100.0, 5.0, 1.0), 200);
  EXPECT_EQ(route_step_budget(0.0), 1);
  // The budget at the oracle's 5 m/s leaves the 1.5x slack of the 3 m/s task speed and more.
  EXPECT_GT(route_step_budget(649.0), 649.0 / (5.0 * 0.1) * 2.0);
}

TEST(ProtocolRecord, RouteCompletionIsWholeAtTheDestination) {
  // The destination fires within 10 m of the terminal waypoint: that is the whole route.
  EXPECT_DOUBLE_EQ(route_completion(275.0, 283.0, env::kDestination), 1.0);
  EXPECT_DOUBLE_EQ(route_completion(141.5, 283.0, env::kOffRoute), 0.5);
  EXPECT_DOUBLE_EQ(route_completion(-3.0, 283.0, env::kCollision), 0.0);
  EXPECT_DOUBLE_EQ(route_completion(700.0, 649.0, env::kTimeLimit), 1.0);
  EXPECT_DOUBLE_EQ(route_completion(5.0, 0.0, env::kStall), 0.0);
}

TEST(ProtocolRecord, ProtocolRecordSucceedsOnlyAtTheDestinationWithoutFailures) {
  const EpisodeSpec spec{.town = "town02",
                         .route = "two_turn",
                         .density = 10,
                         .episode = 4,
                         .traffic_seed = 202,
                         .spawn_seed = 33};
  const EpisodeRecord reached = protocol_record(spec, env::kDestination, 812, 1.0, 3.5);
  EXPECT_TRUE(reached.success);
  EXPECT_EQ(reached.failure_reason, "");
  EXPECT_EQ(reached.town, "town02");
  EXPECT_EQ(reached.route, "two_turn");
  EXPECT_EQ(reached.density, 10);
  EXPECT_EQ(reached.traffic_seed, 202);
  EXPECT_EQ(reached.spawn_seed, 33);
  EXPECT_EQ(reached.episode, 4);
  EXPECT_EQ(reached.steps, 812);
  EXPECT_DOUBLE_EQ(reached.route_completion, 1.0);
  EXPECT_DOUBLE_EQ(reached.episode_return, 3.5);
  // Reaching the destination while colliding is a failure named by the failure event.
  const EpisodeRecord crashed =
      protocol_record(spec, env::kDestination | env::kCollision, 812, 1.0, 0.0);
  EXPECT_FALSE(crashed.success);
  EXPECT_EQ(crashed.failure_reason, env::event_names(env::kCollision));
  const EpisodeRecord timed_out = protocol_record(spec, env::kTimeLimit, 3245, 0.4, 0.0);
  EXPECT_FALSE(timed_out.success);
  EXPECT_EQ(timed_out.failure_reason, env::event_names(env::kTimeLimit));
  // Leaving the route is a failure of its own.
  const EpisodeRecord strayed = protocol_record(spec, env::kOffRoute, 300, 0.2, 0.0);
  EXPECT_FALSE(strayed.success);
  EXPECT_EQ(strayed.failure_reason, "off_route");
  // An episode SUMO failed in is named env_fault, so that reports can leave it out.
  const EpisodeRecord faulted = protocol_record(spec, env::kEnvFault, 120, 0.1, 0.0);
  EXPECT_FALSE(faulted.success);
  EXPECT_EQ(faulted.failure_reason, "env_fault");
}

// A training episode's row: on a route the protocol's verdict and completion; without one
// (pretraining) the time limit alone is a success and completion is 0.
TEST(ProtocolRecord, TrainingRecordJudgesRoutesAsTheProtocolAndFreeDrivingByFailures) {
  TrainingEpisode episode{.town = "town01",
                          .route = "right_loop",
                          .density = 5,
                          .traffic_seed = 123,
                          .spawn_seed = 456,
                          .route_length_m = 400.0,
                          .episode_return = 12.5};
  env::StepResult last;
  last.step = 640;
  last.route_progress_m = 390.0;
  last.events = env::kDestination;
  const EpisodeRecord reached = training_record(episode, last);
  EXPECT_EQ(reached.eval_kind, "training");
  EXPECT_EQ(reached.town, "town01");
  EXPECT_EQ(reached.route, "right_loop");
  EXPECT_EQ(reached.density, 5);
  EXPECT_EQ(reached.traffic_seed, 123);
  EXPECT_EQ(reached.spawn_seed, 456);
  EXPECT_EQ(reached.steps, 640);
  EXPECT_TRUE(reached.success);
  EXPECT_EQ(reached.failure_reason, "");
  EXPECT_DOUBLE_EQ(reached.route_completion, 1.0);  // whole at the destination
  EXPECT_DOUBLE_EQ(reached.episode_return, 12.5);
  last.events = env::kOffRoute;
  last.route_progress_m = 100.0;
  const EpisodeRecord strayed = training_record(episode, last);
  EXPECT_FALSE(strayed.success);
  EXPECT_EQ(strayed.failure_reason, "off_route");
  EXPECT_DOUBLE_EQ(strayed.route_completion, 0.25);
  last.events = env::kTimeLimit;
  EXPECT_FALSE(training_record(episode, last).success) << "a route's time limit is a failure";
  EXPECT_EQ(training_record(episode, last).failure_reason, "time_limit");

  episode.route.clear();
  episode.route_length_m = 0.0;
  const EpisodeRecord free_drive = training_record(episode, last);
  EXPECT_TRUE(free_drive.success) << "without a route the time limit ends a good episode";
  EXPECT_EQ(free_drive.failure_reason, "");
  EXPECT_DOUBLE_EQ(free_drive.route_completion, 0.0);
  last.events = env::kTimeLimit | env::kCollision;
  EXPECT_FALSE(training_record(episode, last).success);
  EXPECT_EQ(training_record(episode, last).failure_reason, "collision");
}

// The grid's route names must mean what they say: `indrive-env routes` once printed "2 turns"
// for `straight`, counting the junctions it crosses; it crosses them without turning.
TEST(ProtocolRecord, BuiltInStraightRoutesCrossJunctionsWithoutTurning) {
  for (const char* name : {"town01", "town02"}) {
    const env::Town town = env::load_town(name);
    const env::Route& straight = env::find_route(town.routes, "straight");
    EXPECT_FALSE(straight.is_loop()) << name;
    EXPECT_FALSE(straight.turns().empty()) << name;
    for (const env::TurnDirection turn : straight.turns()) {
      EXPECT_EQ(turn, env::TurnDirection::kStraight) << name;
    }
  }
}

}  // namespace
}  // namespace indrive::actor
