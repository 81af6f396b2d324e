// indrive-train-local as a process: SIGTERM saves a checkpoint and exits 0, a second start
// resumes it, --evaluate-episodes scores the checkpoint, and a bad key fails with a message.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "indrive/common/run_dir.h"
#include "testing.h"

extern char** environ;

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

// Starts a process with stdout and stderr into `log`; returns its pid.
pid_t spawn(std::vector<std::string> argv, const fs::path& log) {
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, 1, log.c_str(), O_WRONLY | O_CREAT | O_APPEND, 0644);
  posix_spawn_file_actions_adddup2(&actions, 1, 2);
  std::vector<char*> args;
  for (auto& arg : argv) args.push_back(arg.data());
  args.push_back(nullptr);
  // One OpenMP thread, as in local_run_test.cc: the tiny model on a shared two-core machine.
  std::vector<std::string> env_text = {"OMP_NUM_THREADS=1"};
  for (char** e = environ; *e != nullptr; ++e) {
    if (std::string(*e).rfind("OMP_NUM_THREADS=", 0) != 0) env_text.emplace_back(*e);
  }
  std::vector<char*> env;
  for (auto& entry : env_text) env.push_back(entry.data());
  env.push_back(nullptr);
  pid_t pid = -1;
  const int error = posix_spawn(&pid, args[0], &actions, nullptr, args.data(), env.data());
  posix_spawn_file_actions_destroy(&actions);
  if (error != 0) throw std::runtime_error("cannot start " + argv[0]);
  return pid;
}

// Waits for the process; returns its exit code, or -1 (after killing it) on timeout.
int wait_exit(pid_t pid, std::chrono::seconds timeout) {
  const auto end = std::chrono::steady_clock::now() + timeout;
  while (std::chrono::steady_clock::now() < end) {
    int status = 0;
    if (::waitpid(pid, &status, WNOHANG) == pid) {
      return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
    }
    std::this_thread::sleep_for(50ms);
  }
  ::kill(pid, SIGKILL);
  ::waitpid(pid, nullptr, 0);
  return -1;
}

int run(std::vector<std::string> argv, const fs::path& log) {
  return wait_exit(spawn(std::move(argv), log), 300s);
}

std::string read_text(const fs::path& path) {
  std::ifstream in(path);
  std::stringstream text;
  text << in.rdbuf();
  return text.str();
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
  const pid_t pid = spawn(command(run_dir, {}), log);
  // Wait until it has trained a little, then ask it to stop.
  const auto deadline = std::chrono::steady_clock::now() + 240s;
  while (std::chrono::steady_clock::now() < deadline) {
    const auto line = last_metrics(run_dir);
    if (line.is_object() && line.value("updates", 0) > 0) break;
    std::this_thread::sleep_for(200ms);
  }
  ::kill(pid, SIGTERM);
  ASSERT_EQ(wait_exit(pid, 60s), 0) << read_text(log);
  const std::string output = read_text(log);
  EXPECT_NE(output.find("steps "), std::string::npos) << "no progress line:\n" << output;
  const auto checkpoint = CheckpointFiles(run_dir / "checkpoints", 10).newest();
  ASSERT_TRUE(checkpoint.has_value());
  EXPECT_TRUE(fs::exists(run_dir / "coverage.csv"));
  EXPECT_TRUE(fs::exists(run_dir / "config.yaml"));
  const auto stopped_at = last_metrics(run_dir)["env_steps"].get<std::int64_t>();

  // A second start resumes at the saved counters and runs to a budget beyond them.
  const std::int64_t budget = stopped_at + 40;
  ASSERT_EQ(run(command(run_dir, {"--set", "run.budget_env_steps=" + std::to_string(budget)}),
                dir.path() / "resume.log"),
            0)
      << read_text(dir.path() / "resume.log");
  EXPECT_NE(read_text(dir.path() / "resume.log").find("resumed from"), std::string::npos);
  EXPECT_EQ(last_metrics(run_dir)["env_steps"].get<std::int64_t>(), budget);
  EXPECT_EQ(last_metrics(run_dir)["learner_epoch"].get<std::int64_t>(), 2);

  // Evaluation of the newest checkpoint: one episode on the straight route, one CSV row.
  ASSERT_EQ(run(command(run_dir, {"--evaluate-episodes", "1", "--route", "straight", "--set",
                                  "eval.densities=5", "--set", "env.time_limit_steps=60"}),
                dir.path() / "eval.log"),
            0)
      << read_text(dir.path() / "eval.log");
  EXPECT_NE(read_text(dir.path() / "eval.log").find("evaluation local straight: SR"),
            std::string::npos);
  const std::string csv = read_text(run_dir / "eval" / "local-town01-straight.csv");
  EXPECT_EQ(std::count(csv.begin(), csv.end(), '\n'), 2) << csv;
}

TEST(TrainLocalMainTest, BadKeyAndMissingCheckpointFailWithAMessage) {
  testing::TempDir dir;
  const fs::path log = dir.path() / "bad.log";
  EXPECT_EQ(run(command(dir.path() / "runs" / "bad", {"--set", "agent.no_such_key=1"}), log), 1);
  EXPECT_NE(read_text(log).find("no_such_key"), std::string::npos) << read_text(log);
  const fs::path eval_log = dir.path() / "eval.log";
  EXPECT_EQ(run(command(dir.path() / "runs" / "untrained", {"--evaluate-episodes", "1"}), eval_log),
            1);
  EXPECT_NE(read_text(eval_log).find("no checkpoint"), std::string::npos) << read_text(eval_log);
}

}  // namespace
}  // namespace indrive::local
