// The shared command line (process_cli.h) means the same in every program of a run: each one
// given --check-config prints its summary and exits 0 without starting anything, and each one
// refuses a mistyped key with the key named; and each one, running, blocks its stop signals in
// every thread but the one that takes them, and stops on SIGTERM.
#include "indrive/service/process_cli.h"

#include <gtest/gtest.h>
#include <signal.h>

#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <string>
#include <thread>
#include <vector>

#include "child_process.h"
#include "testing.h"

namespace indrive::service {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;

const std::vector<std::vector<std::string>>& programs() {
  static const std::vector<std::vector<std::string>> list = {
      {"indrive-learner"},
      {"indrive-actor"},
      {"indrive-actor", "--evaluate", "--policy", "random"},
      {"indrive-train-local"}};
  return list;
}

std::vector<std::string> command(const std::vector<std::string>& program, const fs::path& run_dir,
                                 std::vector<std::string> extra) {
  std::vector<std::string> argv = {(fs::path(INDRIVE_BIN_DIR) / program.front()).string()};
  argv.insert(argv.end(), program.begin() + 1, program.end());
  for (const std::string& arg : {std::string("--run-dir"), run_dir.string(), std::string("--set"),
                                 std::string("preset=tiny")}) {
    argv.push_back(arg);
  }
  argv.insert(argv.end(), extra.begin(), extra.end());
  return argv;
}

TEST(ProcessCliTest, EveryProgramChecksTheConfigAndStartsNothing) {
  testing::TempDir dir;
  for (const auto& program : programs()) {
    std::string name;
    for (const auto& part : program) name += part + " ";
    SCOPED_TRACE(name);
    const fs::path run_dir = dir.path() / "runs" / "checked";
    const fs::path log = dir.path() / (program.front() + ".log");
    fs::remove(log);
    // None of these runs has a budget: only --check-config can make them end by themselves.
    testing::Child child(command(program, run_dir, {"--check-config"}), log,
                         {{"OMP_NUM_THREADS", "1"}});
    EXPECT_EQ(child.wait(60s), 0) << testing::slurp(log);
    EXPECT_NE(testing::slurp(log).find("config ok: run 'checked', preset tiny"), std::string::npos)
        << testing::slurp(log);
    EXPECT_FALSE(fs::exists(run_dir / "metrics.jsonl"));
    EXPECT_FALSE(fs::exists(run_dir / "checkpoints"));
  }
}

TEST(ProcessCliTest, EveryProgramNamesAMistypedKey) {
  testing::TempDir dir;
  for (const auto& program : programs()) {
    SCOPED_TRACE(program.front());
    const fs::path log = dir.path() / (program.front() + "-typo.log");
    fs::remove(log);
    testing::Child child(command(program, dir.path() / "runs" / "typo",
                                 {"--set", "learner.replay_ration=3", "--check-config"}),
                         log, {{"OMP_NUM_THREADS", "1"}});
    EXPECT_NE(child.wait(60s), 0) << testing::slurp(log);
    EXPECT_NE(testing::slurp(log).find("learner.replay_ratio"), std::string::npos)
        << testing::slurp(log);
  }
}

// Signals run no handler on a computing thread (process_cli.h, install_stop_signals): while
// each program runs, every thread of it blocks SIGINT and SIGTERM (those started before main
// by a shared library too, e.g. OpenBLAS's pool where it is the system BLAS) except the one
// that takes them, and SIGTERM stops it with code 0.
TEST(ProcessCliTest, EveryProgramTakesItsStopSignalsOnOneThreadOnly) {
  testing::TempDir dir;
  // What each program logs once it runs its main loop (the evaluator: its first episode).
  const std::vector<std::string> running = {"ready (epoch", "ready: town", "episode", "kernels:"};
  const int domain = testing::unique_domain_id();
  for (std::size_t p = 0; p < programs().size(); ++p) {
    const auto& program = programs()[p];
    std::string name;
    for (const auto& part : program) name += (name.empty() ? "" : " ") + part;
    SCOPED_TRACE(name);
    const fs::path log = dir.path() / ("running-" + std::to_string(p) + ".log");
    testing::Child child(command(program, dir.path() / "runs" / ("running" + std::to_string(p)),
                                 {"--domain", std::to_string(domain)}),
                         log, {{"OMP_NUM_THREADS", "2"}});
    const auto deadline = std::chrono::steady_clock::now() + 90s;
    while (testing::slurp(log).find(running[p]) == std::string::npos &&
           std::chrono::steady_clock::now() < deadline) {
      std::this_thread::sleep_for(100ms);
    }
    ASSERT_NE(testing::slurp(log).find(running[p]), std::string::npos) << testing::slurp(log);
    std::this_thread::sleep_for(2s);  // its computing threads start with the first products
    const std::vector<testing::ThreadSignals> threads = testing::thread_signals(child.pid());
    int takers = 0;
    for (const testing::ThreadSignals& thread : threads) {
      if (thread.name == "stop-signals") {
        ++takers;
        continue;
      }
      const std::uint64_t stops =
          (std::uint64_t{1} << (SIGINT - 1)) | (std::uint64_t{1} << (SIGTERM - 1));
      EXPECT_EQ(thread.blocked & stops, stops)
          << "thread '" << thread.name << "' (of " << threads.size()
          << ") can take a stop signal: SigBlk " << std::hex << thread.blocked;
    }
    EXPECT_EQ(takers, 1) << threads.size() << " threads";
    std::printf("[figures] %s: %zu threads, SIGINT and SIGTERM blocked in all but stop-signals\n",
                name.c_str(), threads.size());
    child.signal(SIGTERM);
    EXPECT_EQ(child.wait(60s), 0) << testing::slurp(log);
    EXPECT_NE(testing::slurp(log).find("SIGTERM received: stopping"), std::string::npos)
        << testing::slurp(log);
  }
}

}  // namespace
}  // namespace indrive::service
