// The indrive program's subcommands as a user types them (argument parsing, printed figures,
// exit codes); what they draw and compute is tested in plot_test and report_test.
#include <gtest/gtest.h>

#include <chrono>
#include <fstream>

#include "child_process.h"
#include "indrive/agent/agent.h"
#include "indrive/agent/snapshot_file.h"
#include "indrive/nn/serialize.h"
#include "testing.h"

namespace indrive {
namespace {

using namespace std::chrono_literals;

const std::filesystem::path kIndrive = std::filesystem::path(INDRIVE_BIN_DIR) / "indrive";

std::filesystem::path write_run(const std::filesystem::path& dir, double slope) {
  std::filesystem::create_directories(dir);
  std::ofstream out(dir / "metrics.jsonl");
  for (int i = 0; i <= 10; ++i) {
    out << "{\"env_steps\": " << i * 100 << ", \"coverage\": " << slope * i << "}\n";
  }
  return dir;
}

// A typo in an override is refused by the launcher's checks before any process starts, with
// the key named and a non-zero exit; no run folder is made.
TEST(IndriveLaunch, ABadOverrideIsRefusedBeforeAnythingStarts) {
  testing::TempDir dir;
  const auto log = dir.path() / "launch.log";
  testing::Child launch(
      {kIndrive.string(), "launch", "--config",
       std::string(INDRIVE_SOURCE_DIR) + "/deploy/configs/smoke.yaml", "--runs-dir",
       (dir.path() / "runs").string(), "--run-id", "x", "--set", "agent.replay.length=-5"},
      log);
  EXPECT_EQ(launch.wait(60s), 2) << testing::slurp(log);
  const std::string output = testing::slurp(log);
  EXPECT_NE(output.find("refuses the configuration"), std::string::npos) << output;
  EXPECT_NE(output.find("replay.length must be >= 2, got -5"), std::string::npos) << output;
  EXPECT_NE(output.find("nothing was started"), std::string::npos) << output;
  EXPECT_FALSE(std::filesystem::exists(dir.path() / "runs" / "x"));
}

TEST(IndriveCompare, GroupsAndRunsMixAndTheirEndsArePrinted) {
  testing::TempDir dir;
  const auto a = write_run(dir.path() / "s0", 0.01).string();
  const auto b = write_run(dir.path() / "s1", 0.03).string();
  const auto single = write_run(dir.path() / "random", 0.02).string();
  const auto png = dir.path() / "coverage.png";
  const auto log = dir.path() / "compare.log";
  // A --group takes one value: the run after it stays a positional run.
  testing::Child compare({kIndrive.string(), "compare", "--group", "disag=" + a + "," + b, single,
                          "--metric", "coverage", "--out", png.string()},
                         log);
  ASSERT_EQ(compare.wait(30s), 0) << testing::slurp(log);
  EXPECT_TRUE(std::filesystem::exists(png));
  const std::string output = testing::slurp(log);
  EXPECT_NE(output.find("random"), std::string::npos) << output;
  EXPECT_NE(output.find("env_steps 1000: 0.2\n"), std::string::npos) << output;
  EXPECT_NE(output.find("disag (mean of 2, band min-max)"), std::string::npos) << output;
  EXPECT_NE(output.find("env_steps 1000: 0.2 (0.1 to 0.3)"), std::string::npos) << output;
}

// A machine with PLplot but without its cairo driver (plplot-driver-cairo): the plot is an error
// that names the package, where PLplot itself would end the program at its first plot.
TEST(IndriveCompare, AMissingCairoDriverIsAnErrorThatNamesItsPackage) {
  testing::TempDir dir;
  const auto drivers = dir.path() / "drivers";
  std::filesystem::create_directories(drivers);
  int copied = 0;
  for (const auto& entry : std::filesystem::directory_iterator(PLPLOT_DRIVER_DIR)) {
    if (entry.path().stem() == "cairo") continue;
    std::filesystem::copy(entry.path(), drivers / entry.path().filename());
    ++copied;
  }
  ASSERT_GT(copied, 0) << "PLplot ships drivers of its own (null, mem, ps)";
  const auto run = write_run(dir.path() / "s0", 0.01).string();
  const auto log = dir.path() / "compare.log";
  testing::Child compare({kIndrive.string(), "compare", run, "--metric", "coverage", "--out",
                          (dir.path() / "coverage.png").string()},
                         log, {{"PLPLOT_DRV_DIR", drivers.string()}});
  EXPECT_NE(compare.wait(30s), 0);
  EXPECT_NE(testing::slurp(log).find("apt-get install plplot-driver-cairo"), std::string::npos)
      << testing::slurp(log);
  EXPECT_FALSE(std::filesystem::exists(dir.path() / "coverage.png"));
}

TEST(IndriveCompare, NothingToCompareOrABadGroupIsAnErrorThatSaysWhatToWrite) {
  testing::TempDir dir;
  const auto log = dir.path() / "compare.log";
  testing::Child none({kIndrive.string(), "compare", "--metric", "coverage"}, log);
  EXPECT_NE(none.wait(30s), 0);
  EXPECT_NE(testing::slurp(log).find("--group LABEL=RUN"), std::string::npos)
      << testing::slurp(log);

  const auto run = write_run(dir.path() / "s0", 0.01).string();
  const auto bad_log = dir.path() / "bad.log";
  testing::Child bad({kIndrive.string(), "compare", "--group", run, "--metric", "coverage"},
                     bad_log);
  EXPECT_NE(bad.wait(30s), 0);
  EXPECT_NE(testing::slurp(bad_log).find("LABEL=RUN[,RUN...]"), std::string::npos)
      << testing::slurp(bad_log);

  const auto missing_log = dir.path() / "missing.log";
  testing::Child missing(
      {kIndrive.string(), "compare", "--group",
       "disag=" + run + "," + (dir.path() / "nowhere").string(), "--metric", "coverage"},
      missing_log);
  EXPECT_NE(missing.wait(30s), 0);
  EXPECT_NE(testing::slurp(missing_log).find("is not a directory"), std::string::npos)
      << testing::slurp(missing_log);
}

TEST(IndriveDashboard, OneRunsPageGoesIntoTheRunAndItsFiguresArePrinted) {
  testing::TempDir dir;
  const auto run = write_run(dir.path() / "s0", 0.01);
  const auto log = dir.path() / "dashboard.log";
  testing::Child dashboard({kIndrive.string(), "dashboard", run.string()}, log);
  ASSERT_EQ(dashboard.wait(30s), 0) << testing::slurp(log);
  EXPECT_TRUE(std::filesystem::exists(run / "index.html"));
  const std::string output = testing::slurp(log);
  EXPECT_NE(output.find((run / "index.html").string() + ": 1 charts, 11 points"), std::string::npos)
      << output;
}

TEST(IndriveDashboard, SeveralRunsNeedAPageNameAndAFolderThatIsNoRunIsNamed) {
  testing::TempDir dir;
  const auto a = write_run(dir.path() / "s0", 0.01).string();
  const auto b = write_run(dir.path() / "s1", 0.03).string();
  const auto log = dir.path() / "two.log";
  testing::Child two({kIndrive.string(), "dashboard", a, b}, log);
  EXPECT_NE(two.wait(30s), 0);
  EXPECT_NE(testing::slurp(log).find("needs --out PAGE.html"), std::string::npos)
      << testing::slurp(log);

  const auto page = dir.path() / "both.html";
  const auto group_log = dir.path() / "group.log";
  testing::Child group(
      {kIndrive.string(), "dashboard", "--group", "disag=" + a + "," + b, "--out", page.string()},
      group_log);
  EXPECT_EQ(group.wait(30s), 0) << testing::slurp(group_log);
  EXPECT_NE(testing::slurp(page).find("disag (mean of 2, band min-max)"), std::string::npos);

  std::filesystem::create_directories(dir.path() / "notarun");
  const auto bad_log = dir.path() / "bad.log";
  testing::Child bad({kIndrive.string(), "dashboard", (dir.path() / "notarun").string()}, bad_log);
  EXPECT_NE(bad.wait(30s), 0);
  EXPECT_NE(testing::slurp(bad_log).find("is it a run directory"), std::string::npos)
      << testing::slurp(bad_log);
}

// --ended writes how the run ended at the top of a one-off page; --until-eof only goes with
// --watch (the page writer's flags; the pipe itself is page_writer_test's).
TEST(IndriveDashboard, EndedTextOnAOneOffPageAndUntilEofNeedsWatch) {
  testing::TempDir dir;
  const auto run = write_run(dir.path() / "s0", 0.01);
  const auto log = dir.path() / "ended.log";
  testing::Child ended({kIndrive.string(), "dashboard", run.string(), "--ended", "ended: by hand"},
                       log);
  ASSERT_EQ(ended.wait(30s), 0) << testing::slurp(log);
  const std::string page = testing::slurp(run / "index.html");
  EXPECT_NE(page.find("<span class=\"ended\">ended: by hand</span>"), std::string::npos);
  EXPECT_EQ(page.find("http-equiv=\"refresh\""), std::string::npos);

  const auto bad_log = dir.path() / "bad.log";
  testing::Child bad({kIndrive.string(), "dashboard", run.string(), "--until-eof"}, bad_log);
  EXPECT_NE(bad.wait(30s), 0);
  EXPECT_NE(testing::slurp(bad_log).find("--watch"), std::string::npos) << testing::slurp(bad_log);
}

// `indrive snapshot FILE` prints what a file holds; --acting-only writes the slimmer form, which
// the same command then describes; a missing file is refused by name.
TEST(IndriveSnapshot, SaysWhatAFileHoldsAndWritesTheActingOnlyForm) {
  testing::TempDir dir;
  const agent::AgentConfig tiny = agent::preset("tiny");
  agent::Agent agent(tiny);
  const nn::ParamGroup* whole[] = {&agent.world_model().params(),
                                   &agent.exploration().actor_params()};
  const auto old_path = dir.path() / "old.params";
  agent::write_snapshot_file(old_path, nn::save_params(whole), tiny);
  const auto new_path = dir.path() / "acting.params";
  const auto log = dir.path() / "snapshot.log";
  testing::Child snapshot(
      {kIndrive.string(), "snapshot", old_path.string(), "--acting-only", new_path.string()}, log);
  ASSERT_EQ(snapshot.wait(30s), 0) << testing::slurp(log);
  const std::string output = testing::slurp(log);
  EXPECT_NE(output.find("phase = pretrain"), std::string::npos) << output;
  EXPECT_NE(output.find("the whole world model"), std::string::npos) << output;
  EXPECT_NE(output.find(new_path.string() + ": format 1"), std::string::npos) << output;
  EXPECT_NE(output.find("what acting runs"), std::string::npos) << output;
  EXPECT_EQ(agent::read_snapshot_file(new_path).blob, agent.snapshot());

  const auto missing_log = dir.path() / "missing.log";
  testing::Child missing({kIndrive.string(), "snapshot", (dir.path() / "none").string()},
                         missing_log);
  EXPECT_NE(missing.wait(30s), 0);
  EXPECT_NE(testing::slurp(missing_log).find("none"), std::string::npos)
      << testing::slurp(missing_log);
}

// `indrive untrained` writes the initial parameters of a preset's agent, the untrained control:
// the same as an Agent of that preset and seed, and another seed gives other values.
TEST(IndriveUntrained, WritesTheInitialAgentOfAPresetAndSeed) {
  testing::TempDir dir;
  const auto path = dir.path() / "untrained.params";
  const auto other = dir.path() / "untrained-seed-3.params";
  const auto log = dir.path() / "untrained.log";
  testing::Child write({kIndrive.string(), "untrained", "--preset", "tiny", "--out", path.string()},
                       log);
  ASSERT_EQ(write.wait(60s), 0) << testing::slurp(log);
  EXPECT_NE(testing::slurp(log).find("preset = tiny"), std::string::npos) << testing::slurp(log);
  const agent::Agent agent(agent::preset("tiny"));
  EXPECT_EQ(agent::read_snapshot_file(path).blob, agent.snapshot());
  testing::Child seeded(
      {kIndrive.string(), "untrained", "--preset", "tiny", "--seed", "3", "--out", other.string()},
      dir.path() / "seeded.log");
  ASSERT_EQ(seeded.wait(60s), 0);
  EXPECT_NE(agent::read_snapshot_file(other).blob, agent.snapshot());
  const auto bad_log = dir.path() / "bad.log";
  testing::Child bad({kIndrive.string(), "untrained", "--preset", "huge", "--out", path.string()},
                     bad_log);
  EXPECT_NE(bad.wait(30s), 0);
  EXPECT_NE(testing::slurp(bad_log).find("huge"), std::string::npos) << testing::slurp(bad_log);
}

}  // namespace
}  // namespace indrive
