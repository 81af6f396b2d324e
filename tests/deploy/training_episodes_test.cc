// `indrive episodes`: per-route training figures from train-episodes.csv.
#include "indrive/deploy/training_episodes.h"

#include <gtest/gtest.h>

#include "testing.h"

namespace indrive::deploy {
namespace {

EpisodeRecord row(const std::string& route, bool success, double ret, double completion,
                  const std::string& failure = "") {
  return {.run_id = "finetune-lf-disag",
          .method = "disag",
          .eval_kind = "training",
          .task = "lane_following",
          .train_seed = 1,
          .route = route,
          .success = success,
          .failure_reason = success ? "" : failure,
          .route_completion = completion,
          .episode_return = ret};
}

// Per route in the paper's order, the newest N of each route behind the last-N figures, and
// the balanced return as the plain mean of the routes' last-N returns, whatever the draw.
TEST(TrainingEpisodes, PerRouteFiguresAndAReturnBalancedOverRoutes) {
  const std::vector<EpisodeRecord> rows = {
      row("right_loop", false, 40.0, 0.2, "off_route"),
      row("straight", false, 100.0, 0.5, "off_road"),
      row("straight", true, 250.0, 1.0),
      row("right_loop", false, 60.0, 0.3, "off_route"),
      row("straight", true, 260.0, 1.0),
      row("right_loop", false, 80.0, 0.4, "collision"),
  };
  const RunTraining run = summarize_training(rows, 2);
  EXPECT_EQ(run.method, "disag");
  EXPECT_EQ(run.task, "lane_following");
  EXPECT_EQ(run.train_seed, 1);
  EXPECT_EQ(run.episodes, 6);
  ASSERT_EQ(run.routes.size(), 2u);
  const RouteTraining& straight = run.routes[0];
  EXPECT_EQ(straight.route, "straight");
  EXPECT_EQ(straight.episodes, 3);
  EXPECT_EQ(straight.successes, 2);
  EXPECT_DOUBLE_EQ(straight.mean_return, 610.0 / 3);
  EXPECT_DOUBLE_EQ(straight.mean_completion, 2.5 / 3);
  EXPECT_EQ(straight.last, 2);
  EXPECT_DOUBLE_EQ(straight.last_return, 255.0);  // its newest two
  EXPECT_DOUBLE_EQ(straight.last_completion, 1.0);
  EXPECT_EQ(straight.failures.at("off_road"), 1);
  const RouteTraining& loop = run.routes[1];
  EXPECT_EQ(loop.route, "right_loop");
  EXPECT_DOUBLE_EQ(loop.last_return, 70.0);
  EXPECT_EQ(loop.failures.at("off_route"), 2);
  EXPECT_EQ(loop.failures.at("collision"), 1);
  EXPECT_DOUBLE_EQ(run.balanced_last_return, (255.0 + 70.0) / 2);

  // A route with fewer episodes than N uses what it has.
  const RunTraining wide = summarize_training(rows, 10);
  EXPECT_EQ(wide.routes[0].last, 3);
  EXPECT_DOUBLE_EQ(wide.routes[0].last_return, 610.0 / 3);

  const std::string table = render_training({run}, 2);
  EXPECT_NE(table.find("| straight | 3 | 67% | 83% | 203.3 | 100% (2) | 255.0 | off_road 1 |"),
            std::string::npos)
      << table;
  EXPECT_NE(table.find("| right_loop | 3 | 0% | 30% | 60.0 | 35% (2) | 70.0 | off_route 2, "
                       "collision 1 |"),
            std::string::npos)
      << table;
  EXPECT_NE(table.find("last-2 returns): 162.5"), std::string::npos) << table;
}

TEST(TrainingEpisodes, FreeDrivingIsItsOwnRowAndBadInputSaysWhatToDo) {
  const RunTraining run = summarize_training({row("", true, 0.0, 0.0)}, 5);
  ASSERT_EQ(run.routes.size(), 1u);
  EXPECT_NE(render_training({run}, 5).find("| (no route) | 1 | 100% |"), std::string::npos);
  EXPECT_THROW(summarize_training({}, 5), std::invalid_argument);
  EXPECT_THROW(summarize_training({row("straight", true, 1.0, 1.0)}, 0), std::invalid_argument);

  testing::TempDir dir;
  try {
    load_training_episodes(dir.path());
    FAIL();
  } catch (const CsvError& error) {
    EXPECT_NE(std::string(error.what()).find("train-episodes.csv does not exist"),
              std::string::npos)
        << error.what();
  }
  { EpisodeCsvWriter(dir.path() / "train-episodes.csv").write(row("straight", true, 2.0, 1.0)); }
  const auto rows = load_training_episodes(dir.path());
  ASSERT_EQ(rows.size(), 1u);
  EXPECT_EQ(rows[0].route, "straight");
}

}  // namespace
}  // namespace indrive::deploy
