#include "indrive/basics/run_dir.h"

#include <gtest/gtest.h>

#include <fstream>
#include <nlohmann/json.hpp>

#include "testing.h"

namespace indrive {
namespace {

namespace fs = std::filesystem;

TEST(AtomicWrite, ReplacesWholeFileAndLeavesNoTemporary) {
  testing::TempDir dir;
  const fs::path path = dir.path() / "state.bin";
  atomic_write(path, std::string("first version"));
  atomic_write(path, std::string("second"));
  const auto bytes = read_file(path);
  EXPECT_EQ(std::string(bytes.begin(), bytes.end()), "second");
  int files = 0;
  for ([[maybe_unused]] const auto& entry : fs::directory_iterator(dir.path())) ++files;
  EXPECT_EQ(files, 1);
}

TEST(AtomicWrite, MissingFolderIsAClearError) {
  testing::TempDir dir;
  try {
    atomic_write(dir.path() / "no" / "such" / "file.bin", std::string("x"));
    FAIL() << "expected IoError";
  } catch (const IoError& error) {
    EXPECT_NE(std::string(error.what()).find("does the folder exist"), std::string::npos);
  }
  EXPECT_THROW(read_file(dir.path() / "absent"), IoError);
}

TEST(RunDir, CreatesTheLayoutAndRejectsBadIds) {
  testing::TempDir dir;
  const RunDir run = RunDir::open_or_create(dir.path(), "disag-s0");
  EXPECT_TRUE(fs::is_directory(run.checkpoints()));
  EXPECT_TRUE(fs::is_directory(run.eval()));
  EXPECT_TRUE(fs::is_directory(run.plots()));
  EXPECT_TRUE(fs::is_directory(run.videos()));
  EXPECT_EQ(run.metrics_path(), dir.path() / "disag-s0" / "metrics.jsonl");
  EXPECT_THROW(RunDir::open_or_create(dir.path(), "a/b"), std::invalid_argument);
  EXPECT_THROW(RunDir::open_or_create(dir.path(), ""), std::invalid_argument);
}

TEST(CheckpointFiles, KeepsTheNewestNAndIgnoresInterruptedWrites) {
  testing::TempDir dir;
  CheckpointFiles checkpoints(dir.path() / "checkpoints", 2);
  EXPECT_FALSE(checkpoints.newest().has_value());
  const std::vector<std::uint8_t> bytes = {1, 2, 3};
  for (std::uint64_t counter : {10, 200, 30, 4000}) checkpoints.save(counter, bytes);
  const auto files = checkpoints.list();
  ASSERT_EQ(files.size(), 2u);
  EXPECT_EQ(files[0].filename(), "ckpt-000000000200.bin");
  EXPECT_EQ(files[1].filename(), "ckpt-000000004000.bin");
  // A crash between write and rename leaves only a hidden temporary: never picked up.
  std::ofstream(dir.path() / "checkpoints" / ".ckpt-000000009999.bin.tmp-1") << "partial";
  EXPECT_EQ(checkpoints.newest()->filename(), "ckpt-000000004000.bin");
}

TEST(CheckpointFiles, PathNamesTheFileThatSaveWrites) {
  testing::TempDir dir;
  CheckpointFiles checkpoints(dir.path(), 2);
  EXPECT_EQ(checkpoints.path(42), dir.path() / "ckpt-000000000042.bin");
  EXPECT_EQ(checkpoints.save(42, std::vector<std::uint8_t>{1}), checkpoints.path(42));
}

TEST(PassedMultiple, OnlyWhenACounterCrossesAMultiple) {
  EXPECT_TRUE(passed_multiple(990, 1008, 1000));
  EXPECT_TRUE(passed_multiple(999, 1000, 1000));
  EXPECT_TRUE(passed_multiple(0, 2500, 1000));
  EXPECT_FALSE(passed_multiple(1000, 1999, 1000));
  EXPECT_FALSE(passed_multiple(1008, 1008, 1000));
  EXPECT_FALSE(passed_multiple(0, 5000, 0));  // off
}

TEST(EpisodeStats, IntervalMeansAndTheNewestWindowOfEpisodes) {
  EpisodeStats episodes(/*window=*/3);
  nlohmann::json empty;
  episodes.write(empty);
  EXPECT_TRUE(empty.empty()) << "no episode, no keys: " << empty.dump();

  episodes.add(100, 2);
  episodes.add(300, 6);
  nlohmann::json first;
  episodes.write(first);
  EXPECT_DOUBLE_EQ(first.at("episode_length").get<double>(), 200.0);
  EXPECT_DOUBLE_EQ(first.at("episode_reach").get<double>(), 4.0);
  EXPECT_DOUBLE_EQ(first.at("episode_length_last3").get<double>(), 200.0);
  EXPECT_DOUBLE_EQ(first.at("episode_reach_last3").get<double>(), 4.0);

  episodes.add(50, 1);
  episodes.add(10, 9);  // pushes the first episode out of the window of 3
  nlohmann::json second;
  episodes.write(second);
  EXPECT_DOUBLE_EQ(second.at("episode_length").get<double>(), 30.0);
  EXPECT_DOUBLE_EQ(second.at("episode_reach").get<double>(), 5.0);
  EXPECT_DOUBLE_EQ(second.at("episode_length_last3").get<double>(), 120.0);
  EXPECT_DOUBLE_EQ(second.at("episode_reach_last3").get<double>(), 16.0 / 3.0);

  nlohmann::json quiet;  // no episode since the last line: only the window's means remain
  episodes.write(quiet);
  EXPECT_FALSE(quiet.contains("episode_reach")) << quiet.dump();
  EXPECT_DOUBLE_EQ(quiet.at("episode_reach_last3").get<double>(), 16.0 / 3.0);
  EXPECT_THROW(EpisodeStats(0), std::invalid_argument);
}

TEST(MetricsLog, AppendsOneParsableObjectPerLine) {
  testing::TempDir dir;
  const fs::path path = dir.path() / "metrics.jsonl";
  {
    MetricsLog metrics(path);
    metrics.write({{"env_steps", 100}, {"loss", 1.5}});
  }
  {
    MetricsLog metrics(path);  // reopening appends, as after a restart
    metrics.write({{"env_steps", 200}, {"time", 7.0}});
  }
  std::ifstream in(path);
  std::vector<nlohmann::json> lines;
  for (std::string line; std::getline(in, line);) lines.push_back(nlohmann::json::parse(line));
  ASSERT_EQ(lines.size(), 2u);
  EXPECT_EQ(lines[0]["env_steps"], 100);
  EXPECT_TRUE(lines[0].contains("time"));
  EXPECT_EQ(lines[1]["time"], 7.0);
}

}  // namespace
}  // namespace indrive
