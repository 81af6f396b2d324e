// The shared command line (process_cli.h) means the same in every program of a run: each one
// given --check-config prints its summary and exits 0 without starting anything, and each one
// refuses a mistyped key with the key named.
#include "indrive/service/process_cli.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <string>
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

}  // namespace
}  // namespace indrive::service
