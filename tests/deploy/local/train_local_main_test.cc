// indrive-train-local as a process: SIGTERM saves a checkpoint and exits 0, a second start
// resumes it, --evaluate-episodes scores the checkpoint, a bad key fails with a message, and
// --check-config only checks.
#include <gtest/gtest.h>
#include <signal.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <thread>
#include <vector>

#include "child_process.h"
#include "indrive/basics/run_dir.h"
#include "testing.h"

namespace indrive::local {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;

std::vector<std::string> command(const fs::path& run_dir, std::vector<std::string> extra) {
  std::vector<std::string> args = {std::string(INDRIVE_BIN_DIR) + "/indrive-train-local",
                                   "--config",
                                   testing::source_path("deploy/configs/smoke.yaml").string(),
                                   "--run-dir",
                                   run_dir.string(),
                                   "--set",
                                   "env.densities=5",
                                   "--set",
                                   "agent.replay.prefill=64",
                                   "--set",
                                   "learner.log_interval_s=0.5",
                                   "--set",
                                   "run.budget_env_steps=0"};
  args.insert(args.end(), extra.begin(), extra.end());
  return args;
}

// One OpenMP thread, as in local_run_test.cc: the tiny model on a shared two-core machine.
const std::map<std::string, std::string> kOneThread = {{"OMP_NUM_THREADS", "1"}};

// Runs a program to its end; its exit code, or -1 (killed) after 300 s.
int run(std::vector<std::string> argv, const fs::path& log) {
  return testing::Child(std::move(argv), log, kOneThread).wait(300s);
}

// The last metrics line, or null when there is none yet.
nlohmann::json last_metrics(const fs::path& run_dir) {
  std::ifstream in(run_dir / "metrics.jsonl");
  nlohmann::json last;
  for (std::string line; std::getline(in, line);) {
    if (!line.empty()) last = nlohmann::json::parse(line, nullptr, /*allow_exceptions=*/false);
  }
  return last;
}

TEST(TrainLocalMainTest, SigtermCheckpointsAndTheNextStartResumesAndEvaluates) {
  testing::TempDir dir;
  const fs::path run_dir = dir.path() / "runs" / "local";
  const fs::path log = dir.path() / "train.log";
  testing::Child trainer(command(run_dir, {}), log, kOneThread);
  // Wait until it has trained a little, then ask it to stop.
  const auto deadline = std::chrono::steady_clock::now() + 240s;
  while (std::chrono::steady_clock::now() < deadline) {
    const auto line = last_metrics(run_dir);
    if (line.is_object() && line.value("updates", 0) > 0) break;
    std::this_thread::sleep_for(200ms);
  }
  trainer.signal(SIGTERM);
  ASSERT_EQ(trainer.wait(60s), 0) << testing::slurp(log);
  const std::string output = testing::slurp(log);
  EXPECT_NE(output.find("steps "), std::string::npos) << "no progress line:\n" << output;
  const auto checkpoint = CheckpointFiles(run_dir / "checkpoints", 10).newest();
  ASSERT_TRUE(checkpoint.has_value());
  EXPECT_TRUE(fs::exists(run_dir / "coverage.csv"));
  EXPECT_TRUE(fs::exists(run_dir / "config.yaml"));
  const auto stopped_at = last_metrics(run_dir)["env_steps"].get<std::int64_t>();
  // Its page (learner.dashboard_s, 30 s by default) says how it ended.
  EXPECT_NE(testing::slurp(run_dir / "index.html")
                .find("<span class=\"ended\">ended: stopped by a signal at "),
            std::string::npos)
      << testing::slurp(run_dir / "logs" / "dashboard.log");

  // A second start resumes at the saved counters and runs to a budget beyond them.
  const std::int64_t budget = stopped_at + 40;
  ASSERT_EQ(run(command(run_dir, {"--set", "run.budget_env_steps=" + std::to_string(budget)}),
                dir.path() / "resume.log"),
            0)
      << testing::slurp(dir.path() / "resume.log");
  EXPECT_NE(testing::slurp(dir.path() / "resume.log").find("resumed from"), std::string::npos);
  EXPECT_EQ(last_metrics(run_dir)["env_steps"].get<std::int64_t>(), budget);
  EXPECT_EQ(last_metrics(run_dir)["learner_epoch"].get<std::int64_t>(), 2);
  EXPECT_NE(testing::slurp(run_dir / "index.html")
                .find("ended: budget reached at " + std::to_string(budget) + " env steps"),
            std::string::npos);

  // Evaluation of the newest checkpoint: one episode on the straight route, one CSV row (a
  // short step budget: the route at 20 m/s).
  ASSERT_EQ(run(command(run_dir, {"--evaluate-episodes", "1", "--route", "straight", "--set",
                                  "eval.densities=5", "--set", "eval.budget_speed_mps=20"}),
                dir.path() / "eval.log"),
            0)
      << testing::slurp(dir.path() / "eval.log");
  EXPECT_NE(testing::slurp(dir.path() / "eval.log").find("evaluation local straight: SR"),
            std::string::npos);
  const std::string csv = testing::slurp(run_dir / "eval" / "local-town01-straight.csv");
  EXPECT_EQ(std::count(csv.begin(), csv.end(), '\n'), 2) << csv;
}

TEST(TrainLocalMainTest, BadKeyAndMissingCheckpointFailWithAMessage) {
  testing::TempDir dir;
  const fs::path log = dir.path() / "bad.log";
  EXPECT_EQ(run(command(dir.path() / "runs" / "bad", {"--set", "agent.no_such_key=1"}), log), 1);
  EXPECT_NE(testing::slurp(log).find("no_such_key"), std::string::npos) << testing::slurp(log);
  const fs::path eval_log = dir.path() / "eval.log";
  EXPECT_EQ(run(command(dir.path() / "runs" / "untrained", {"--evaluate-episodes", "1"}), eval_log),
            1);
  EXPECT_NE(testing::slurp(eval_log).find("no checkpoint"), std::string::npos)
      << testing::slurp(eval_log);
}

// --check-config resolves the configuration, prints its summary and exits without training (it
// once started a run that trained until stopped): no metrics, no checkpoint.
TEST(TrainLocalMainTest, CheckConfigPrintsASummaryAndTrainsNothing) {
  testing::TempDir dir;
  const fs::path run_dir = dir.path() / "runs" / "checked";
  const fs::path log = dir.path() / "check.log";
  // The run has no budget (0): only --check-config can make it end by itself.
  EXPECT_EQ(testing::Child(command(run_dir, {"--check-config"}), log, kOneThread).wait(60s), 0)
      << testing::slurp(log);
  EXPECT_NE(testing::slurp(log).find("config ok: run 'checked', preset tiny"), std::string::npos)
      << testing::slurp(log);
  EXPECT_FALSE(fs::exists(run_dir / "metrics.jsonl"));
  EXPECT_FALSE(fs::exists(run_dir / "checkpoints"));
}

}  // namespace
}  // namespace indrive::local
