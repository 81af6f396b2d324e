// train-episodes.csv as both training programs write it (TrainingEpisodes): the run's labels on
// every row, episodes numbered on across sessions, and a file that cannot be written costing the
// rows, not the run.
#include "indrive/learner/training_episodes.h"

#include <gtest/gtest.h>

#include "testing.h"

namespace indrive::learner {
namespace {

const TrainingRunLabels kLabels{.method = "icm", .task = "exploration", .train_seed = 2};

TEST(TrainingEpisodes, RowsCarryTheRunsLabelsAndAResumedRunNumbersOn) {
  testing::TempDir dir;
  const auto path = dir.path() / "train-episodes.csv";
  {
    TrainingEpisodes episodes(path, kLabels);
    EXPECT_FALSE(std::filesystem::exists(path)) << "opened at the first episode, not before";
    episodes.write({.run_id = "r", .method = "ignored", .policy_version = 3, .steps = 150});
    episodes.write({.run_id = "r", .episode = 41, .steps = 90});
    EXPECT_EQ(episodes.rows(), 2);
  }
  TrainingEpisodes resumed(path, kLabels);
  resumed.write({.run_id = "r", .steps = 20});
  const auto rows = read_episode_csv(path);
  ASSERT_EQ(rows.size(), 3u);
  for (int i = 0; i < 3; ++i) {
    EXPECT_EQ(rows[i].episode, i);
    EXPECT_EQ(rows[i].method, "icm");
    EXPECT_EQ(rows[i].eval_kind, "training");
    EXPECT_EQ(rows[i].task, "exploration");
    EXPECT_EQ(rows[i].train_seed, 2);
    EXPECT_EQ(rows[i].run_id, "r");
  }
  EXPECT_EQ(rows[0].policy_version, 3);
  EXPECT_EQ(rows[1].steps, 90);
}

TEST(TrainingEpisodes, AFileThatCannotBeWrittenDoesNotStopTheRun) {
  testing::TempDir dir;
  // A directory where the file should be: opening it fails at every episode.
  const auto path = dir.path() / "train-episodes.csv";
  std::filesystem::create_directories(path);
  TrainingEpisodes episodes(path, kLabels);
  EXPECT_NO_THROW(episodes.write({.run_id = "r"}));
  EXPECT_NO_THROW(episodes.write({.run_id = "r"}));
  EXPECT_EQ(episodes.rows(), 0);
}

}  // namespace
}  // namespace indrive::learner
