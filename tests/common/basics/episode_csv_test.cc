#include "indrive/basics/episode_csv.h"

#include <gtest/gtest.h>

#include <fstream>
#include <string>

#include "testing.h"

namespace indrive {
namespace {

EpisodeRecord sample(int episode, bool success) {
  return {.run_id = "disag-s0",
          .method = "disag",
          .eval_kind = "zero_shot",
          .task = "exploration",
          .train_seed = 0,
          .policy_version = 42,
          .town = "my, town",
          .route = "straight",
          .density = 10,
          .traffic_seed = 1,
          .spawn_seed = 2,
          .episode = episode,
          .success = success,
          .failure_reason = success ? "" : "collision",
          .steps = 321,
          .route_completion = 0.5,
          .episode_return = -1.25};
}

TEST(EpisodeCsv, RoundTripsRecordsIncludingQuotedFields) {
  testing::TempDir dir;
  const auto path = dir.path() / "eval.csv";
  {
    EpisodeCsvWriter writer(path);
    writer.write(sample(0, true));
  }
  {
    EpisodeCsvWriter writer(path);  // appending does not repeat the header
    writer.write(sample(1, false));
  }
  const auto records = read_episode_csv(path);
  ASSERT_EQ(records.size(), 2u);
  EXPECT_EQ(records[0].town, "my, town");
  EXPECT_TRUE(records[0].success);
  EXPECT_EQ(records[1].failure_reason, "collision");
  EXPECT_EQ(records[1].policy_version, 42);
  EXPECT_DOUBLE_EQ(records[1].episode_return, -1.25);
  EXPECT_DOUBLE_EQ(records[1].route_completion, 0.5);
}

// A crash while a row was written leaves a partial last line; opening the file again cuts it
// off, so the rows appended after it stay readable, and rows() counts the complete ones.
TEST(EpisodeCsv, AWriterCutsARowLeftPartialByACrashAndCountsTheRows) {
  testing::TempDir dir;
  const auto path = dir.path() / "train-episodes.csv";
  {
    EpisodeCsvWriter writer(path);
    EXPECT_EQ(writer.rows(), 0);
    writer.write(sample(0, true));
    writer.write(sample(1, false));
    EXPECT_EQ(writer.rows(), 2);
  }
  { std::ofstream(path, std::ios::app) << "disag-s0,disag,zero_sh"; }  // the crash
  {
    EpisodeCsvWriter writer(path);
    EXPECT_EQ(writer.rows(), 2);
    writer.write(sample(2, true));
    EXPECT_EQ(writer.rows(), 3);
  }
  const auto records = read_episode_csv(path);
  ASSERT_EQ(records.size(), 3u);
  EXPECT_EQ(records[2].episode, 2);
  EXPECT_EQ(EpisodeCsvWriter(path).rows(), 3);
}

// A field with a line break is refused before anything is written: the files are read line by
// line, and a reopening writer counts and cuts rows at line ends.
TEST(EpisodeCsv, AFieldWithALineBreakIsRefusedAndNothingIsWritten) {
  testing::TempDir dir;
  const auto path = dir.path() / "eval.csv";
  EpisodeCsvWriter writer(path);
  writer.write(sample(0, true));
  for (const std::string route : {"two\nlines", "carriage\rreturn"}) {
    EpisodeRecord bad = sample(1, false);
    bad.route = route;
    EXPECT_THROW(writer.write(bad), CsvError) << route;
  }
  EXPECT_EQ(writer.rows(), 1);
  EXPECT_EQ(EpisodeCsvWriter(path).rows(), 1);
  ASSERT_EQ(read_episode_csv(path).size(), 1u);
}

TEST(EpisodeCsv, APartialRowOrWrongHeaderIsAClearError) {
  testing::TempDir dir;
  const auto path = dir.path() / "eval.csv";
  { EpisodeCsvWriter(path).write(sample(0, true)); }
  { std::ofstream(path, std::ios::app) << "disag-s0,disag,zero_shot\n"; }
  try {
    read_episode_csv(path);
    FAIL();
  } catch (const CsvError& error) {
    EXPECT_NE(std::string(error.what()).find("eval.csv:3: 3 fields, expected 19"),
              std::string::npos)
        << error.what();
  }
  const auto other = dir.path() / "other.csv";
  { std::ofstream(other) << "a,b,c\n1,2,3\n"; }
  EXPECT_THROW(read_episode_csv(other), CsvError);
}

TEST(EpisodeCsv, ProtocolAndLaneInvasionsRoundTrip) {
  testing::TempDir dir;
  const auto path = dir.path() / "eval.csv";
  EpisodeRecord code = sample(0, true);
  code.protocol = "indrive_code";
  code.lane_invasions = 7;
  { EpisodeCsvWriter(path).write(code); }
  const auto records = read_episode_csv(path);
  ASSERT_EQ(records.size(), 1u);
  EXPECT_EQ(records[0].protocol, "indrive_code");
  EXPECT_EQ(records[0].lane_invasions, 7);
  // An unknown protocol is refused.
  {
    std::ofstream(path, std::ios::app) << "r,m,zero_shot,t,0,1,town01,straight,5,1,1,0,1,,10,1,0,"
                                          "loose,0\n";
  }
  EXPECT_THROW(read_episode_csv(path), CsvError);
}

// Files of older builds (no protocol column) stay readable as strict evaluations, and a
// resumed run appends strict rows in their columns; a row of another protocol is refused.
TEST(EpisodeCsv, FilesWithoutTheProtocolColumnReadAsStrict) {
  testing::TempDir dir;
  const auto path = dir.path() / "old.csv";
  {
    std::ofstream(path) << episode_csv_header_v1() << "\n"
                        << "r,disag,zero_shot,exploration,0,3,town01,straight,5,101,11,0,0,"
                           "lane_invasion,40,0.1,0\n";
  }
  {
    EpisodeCsvWriter writer(path);
    writer.write(sample(1, true));
    EpisodeRecord code = sample(2, true);
    code.protocol = "indrive_code";
    EXPECT_THROW(writer.write(code), CsvError);
  }
  const auto records = read_episode_csv(path);
  ASSERT_EQ(records.size(), 2u);
  EXPECT_EQ(records[0].protocol, "strict");
  EXPECT_EQ(records[0].lane_invasions, 1);  // lane_invasion ended it
  EXPECT_EQ(records[1].protocol, "strict");
  EXPECT_EQ(records[1].lane_invasions, 0);
}

}  // namespace
}  // namespace indrive
