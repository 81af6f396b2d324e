#include "indrive/deploy/supervisor.h"

#include <gtest/gtest.h>
#include <signal.h>

#include <chrono>
#include <fstream>
#include <thread>

#include "testing.h"

namespace indrive::deploy {
namespace {

using namespace std::chrono_literals;

// Polls until the supervisor has nothing left or `limit` passes.
void run_until_done(Supervisor& supervisor, std::chrono::seconds limit) {
  const auto deadline = std::chrono::steady_clock::now() + limit;
  while (supervisor.poll(20ms) && std::chrono::steady_clock::now() < deadline) {
  }
}

ChildStatus status_of(const Supervisor& supervisor, const std::string& name) {
  for (const auto& status : supervisor.status()) {
    if (status.name == name) return status;
  }
  ADD_FAILURE() << "no child " << name;
  return {};
}

TEST(Supervisor, CollectsEveryOutputLineInOrderAndReportsExit) {
  Supervisor supervisor;
  supervisor.add({.name = "printer",
                  .argv = {"sh", "-c", "for i in 1 2 3; do echo line $i; done; echo oops >&2"}});
  std::vector<std::string> lines;
  supervisor.on_line([&](const std::string& name, const std::string& line) {
    EXPECT_EQ(name, "printer");
    lines.push_back(line);
  });
  supervisor.start();
  run_until_done(supervisor, 10s);
  EXPECT_EQ(lines, (std::vector<std::string>{"line 1", "line 2", "line 3", "oops"}));
  const auto status = status_of(supervisor, "printer");
  EXPECT_EQ(status.state, ChildState::kExited);
  EXPECT_EQ(status.last_exit_code, 0);
  EXPECT_EQ(status.restarts, 0);
}

TEST(Supervisor, RestartsAFailingChildWithGrowingBackoffUpToTheLimit) {
  testing::TempDir dir;
  const auto stamps = dir.path() / "stamps";
  Supervisor supervisor;
  supervisor.add({.name = "crasher",
                  .argv = {"sh", "-c", "date +%s.%N >> " + stamps.string() + "; exit 3"},
                  .restart = RestartPolicy::kOnFailure,
                  .backoff = {.initial_s = 0.1, .factor = 2.0, .max_s = 1.0, .max_restarts = 3}});
  supervisor.start();
  run_until_done(supervisor, 20s);
  const auto status = status_of(supervisor, "crasher");
  EXPECT_EQ(status.restarts, 3);
  EXPECT_EQ(status.state, ChildState::kFailed);
  EXPECT_EQ(status.last_exit_code, 3);
  // Four starts; the gaps between them are at least the back-off delays 0.1, 0.2, 0.4 s.
  std::ifstream in(stamps);
  std::vector<double> starts;
  for (double t; in >> t;) starts.push_back(t);
  ASSERT_EQ(starts.size(), 4u);
  EXPECT_GE(starts[1] - starts[0], 0.1 - 0.02);
  EXPECT_GE(starts[2] - starts[1], 0.2 - 0.02);
  EXPECT_GE(starts[3] - starts[2], 0.4 - 0.02);
}

TEST(Supervisor, RestartsAChildKilledWithSigkill) {
  Supervisor supervisor;
  supervisor.add({.name = "actor-0",
                  .argv = {"sleep", "30"},
                  .restart = RestartPolicy::kOnFailure,
                  .backoff = {.initial_s = 0.05}});
  supervisor.start();
  const pid_t first_pid = status_of(supervisor, "actor-0").pid;
  ASSERT_GT(first_pid, 0);
  ASSERT_TRUE(supervisor.signal_child("actor-0", SIGKILL));
  const auto deadline = std::chrono::steady_clock::now() + 10s;
  while (status_of(supervisor, "actor-0").restarts == 0 &&
         std::chrono::steady_clock::now() < deadline) {
    supervisor.poll(20ms);
  }
  const auto status = status_of(supervisor, "actor-0");
  EXPECT_EQ(status.restarts, 1);
  EXPECT_EQ(status.last_exit_code, 128 + SIGKILL);
  EXPECT_EQ(status.state, ChildState::kRunning);
  EXPECT_NE(status.pid, first_pid);
  supervisor.stop(2s);
  EXPECT_EQ(status_of(supervisor, "actor-0").state, ChildState::kExited);
}

TEST(Supervisor, StopKillsAChildThatIgnoresSigterm) {
  Supervisor supervisor;
  supervisor.add({.name = "stubborn", .argv = {"sh", "-c", "trap '' TERM; echo ready; sleep 30"}});
  bool ready = false;
  supervisor.on_line([&](const std::string&, const std::string& line) { ready = line == "ready"; });
  supervisor.start();
  while (!ready) supervisor.poll(20ms);
  const auto before = std::chrono::steady_clock::now();
  supervisor.stop(300ms);
  EXPECT_LT(std::chrono::steady_clock::now() - before, 10s);
  const auto status = status_of(supervisor, "stubborn");
  EXPECT_EQ(status.state, ChildState::kExited);
  EXPECT_EQ(status.last_exit_code, 128 + SIGKILL);
}

TEST(Supervisor, AnEssentialChildEndingStopsSupervision) {
  Supervisor supervisor;
  supervisor.add({.name = "learner", .argv = {"sh", "-c", "exit 0"}, .essential = true});
  supervisor.add({.name = "actor-0", .argv = {"sleep", "30"}});
  supervisor.start();
  run_until_done(supervisor, 10s);
  EXPECT_EQ(status_of(supervisor, "learner").state, ChildState::kExited);
  EXPECT_EQ(status_of(supervisor, "actor-0").state, ChildState::kRunning);
  supervisor.stop(2s);
}

TEST(Supervisor, ChildrenThatFinishTheRunOutliveTheEssentialOneAndTheOthersAreStopped) {
  Supervisor supervisor;
  supervisor.add({.name = "learner", .argv = {"sh", "-c", "exit 0"}, .essential = true});
  supervisor.add(
      {.name = "actor-0", .argv = {"sleep", "30"}, .restart = RestartPolicy::kOnFailure});
  supervisor.add(
      {.name = "evaluator-0", .argv = {"sh", "-c", "sleep 1; exit 0"}, .finishes_run = true});
  supervisor.start();
  const auto before = std::chrono::steady_clock::now();
  run_until_done(supervisor, 10s);
  // Supervision lasted until the evaluator's own end, not the learner's.
  EXPECT_GE(std::chrono::steady_clock::now() - before, 900ms);
  EXPECT_EQ(status_of(supervisor, "evaluator-0").state, ChildState::kExited);
  EXPECT_EQ(status_of(supervisor, "evaluator-0").last_exit_code, 0);
  // The actor was stopped with SIGTERM and not restarted; being stopped is not a failure,
  // although `sleep` ends by the signal.
  const auto actor = status_of(supervisor, "actor-0");
  EXPECT_EQ(actor.state, ChildState::kExited);
  EXPECT_EQ(actor.last_exit_code, 128 + SIGTERM);
  EXPECT_EQ(actor.restarts, 0);
  supervisor.stop(2s);
}

TEST(Supervisor, AMissingExecutableIsAClearError) {
  Supervisor supervisor;
  supervisor.add({.name = "ghost", .argv = {"indrive-no-such-program"}});
  try {
    supervisor.start();
    FAIL() << "expected LaunchError";
  } catch (const LaunchError& error) {
    EXPECT_NE(std::string(error.what()).find("cannot start 'ghost'"), std::string::npos)
        << error.what();
    EXPECT_NE(std::string(error.what()).find("No such file"), std::string::npos) << error.what();
  }
}

}  // namespace
}  // namespace indrive::deploy
