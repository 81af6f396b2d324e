#include "indrive/deploy/launch.h"

#include <gtest/gtest.h>
#include <signal.h>

#include <algorithm>
#include <cstdlib>
#include <fstream>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <utility>

#include "child_process.h"
#include "testing.h"

namespace indrive::deploy {
namespace {

// How the children's idle OpenMP threads wait: passive after a short spin, unless the user's
// environment says otherwise (read once by each child when it loads OpenMP).
TEST(LaunchPlan, OpenMpWaitDefaultsLeaveTheUsersValues) {
  const auto value = [](const char* name) {
    const char* v = std::getenv(name);
    return v ? std::string(v) : std::string("(unset)");
  };
  const std::string policy = value("OMP_WAIT_POLICY"), spin = value("GOMP_SPINCOUNT");
  ::unsetenv("OMP_WAIT_POLICY");
  ::unsetenv("GOMP_SPINCOUNT");
  set_openmp_wait_defaults();
  EXPECT_EQ(value("OMP_WAIT_POLICY"), "passive");
  EXPECT_EQ(value("GOMP_SPINCOUNT"), "100000");
  ::setenv("OMP_WAIT_POLICY", "active", 1);
  ::setenv("GOMP_SPINCOUNT", "0", 1);
  set_openmp_wait_defaults();
  EXPECT_EQ(value("OMP_WAIT_POLICY"), "active");
  EXPECT_EQ(value("GOMP_SPINCOUNT"), "0");
  for (const auto& [name, old] : {std::pair{"OMP_WAIT_POLICY", policy}, {"GOMP_SPINCOUNT", spin}}) {
    if (old == "(unset)")
      ::unsetenv(name);
    else
      ::setenv(name, old.c_str(), 1);
  }
}

TEST(LaunchPlan, StartsOneLearnerActorsAndEvaluatorsWithSharedArguments) {
  testing::TempDir dir;
  const LaunchOptions options{.config = "smoke.yaml",
                              .runs_dir = dir.path(),
                              .run_id = "smoke",
                              .actors = 2,
                              .evaluators = 1,
                              .domain_id = 7,
                              .dds_security = "/srv/run-security",
                              .overrides = {"train.updates=10"},
                              .bin_dir = "/opt/indrive/bin"};
  const auto plan = launch_plan(options);
  ASSERT_EQ(plan.size(), 4u);
  EXPECT_EQ(plan[0].name, "learner");
  EXPECT_TRUE(plan[0].essential);
  EXPECT_FALSE(plan[0].finishes_run);
  EXPECT_EQ(plan[0].restart, RestartPolicy::kOnFailure);  // resumes from its checkpoint
  EXPECT_GT(plan[0].backoff.max_restarts, 0);
  EXPECT_EQ(plan[0].argv[0], "/opt/indrive/bin/indrive-learner");
  // The launcher writes the run's page: the learner's own page writer stays off, last word.
  ASSERT_GE(plan[0].argv.size(), 2u);
  EXPECT_EQ(plan[0].argv[plan[0].argv.size() - 2], "--set");
  EXPECT_EQ(plan[0].argv.back(), "learner.dashboard_s=0");
  EXPECT_EQ(plan[1].name, "actor-0");
  EXPECT_EQ(plan[2].name, "actor-1");
  EXPECT_EQ(plan[2].restart, RestartPolicy::kOnFailure);
  EXPECT_EQ(plan[3].name, "evaluator-0");
  EXPECT_EQ(plan[3].argv[1], "--evaluate");
  EXPECT_TRUE(plan[3].finishes_run);  // evaluates the final snapshot after the learner ends
  EXPECT_FALSE(plan[1].finishes_run);
  for (const auto& spec : plan) {
    const auto& a = spec.argv;
    auto after = [&](const std::string& flag) {
      const auto it = std::find(a.begin(), a.end(), flag);
      return it == a.end() || it + 1 == a.end() ? std::string() : *(it + 1);
    };
    EXPECT_EQ(after("--config"), "smoke.yaml") << spec.name;
    EXPECT_EQ(after("--run-dir"), (dir.path() / "smoke").string()) << spec.name;
    EXPECT_EQ(after("--domain"), "7") << spec.name;
    // One folder for all: each program picks its own role's files from it.
    EXPECT_EQ(after("--dds-security"), "/srv/run-security") << spec.name;
    EXPECT_EQ(after("--set"), "train.updates=10") << spec.name;
    EXPECT_EQ(spec.log_file.parent_path(), dir.path() / "smoke" / "logs") << spec.name;
  }
  // The plan alone makes no folder: a launch that its checks refuse leaves nothing behind.
  EXPECT_FALSE(std::filesystem::exists(dir.path() / "smoke"));
}

TEST(LaunchStatus, StatusJsonHasEveryProcessAndTheRunsState) {
  testing::TempDir dir;
  std::vector<ChildStatus> processes = {
      {.name = "learner", .state = ChildState::kRunning, .pid = 42, .last_line = "steps 100"},
      {.name = "actor-0",
       .state = ChildState::kWaitingRestart,
       .restarts = 2,
       .last_exit_code = 134}};
  write_status_json(dir.path(), processes, /*ended=*/false);
  auto status = nlohmann::json::parse(testing::slurp(dir.path() / "status.json"));
  EXPECT_EQ(status["state"], "running");
  ASSERT_EQ(status["processes"].size(), 2u);
  EXPECT_EQ(status["processes"][0]["name"], "learner");
  EXPECT_EQ(status["processes"][0]["pid"], 42);
  EXPECT_EQ(status["processes"][0]["last_line"], "steps 100");
  EXPECT_EQ(status["processes"][1]["state"], child_state_name(ChildState::kWaitingRestart));
  EXPECT_EQ(status["processes"][1]["restarts"], 2);
  EXPECT_EQ(status["processes"][1]["last_exit_code"], 134);
  write_status_json(dir.path(), processes, /*ended=*/true);
  status = nlohmann::json::parse(testing::slurp(dir.path() / "status.json"));
  EXPECT_EQ(status["state"], "ended");
}

// A launch of stand-in programs: a "learner" that logs three metrics lines and ends the run (a
// clean exit; a failed one would be restarted), and an
// "actor" that waits to be stopped. The run's page is refreshed while it runs and written a
// last time with the learner's exit code.
TEST(LaunchPage, TheRunsPageIsRefreshedWhileItRunsAndSaysHowItEnded) {
  testing::TempDir dir;
  const auto bin = dir.path() / "bin";
  std::filesystem::create_directories(bin);
  {
    std::ofstream learner(bin / "indrive-learner");
    learner << "#!/bin/sh\n"
               "case \" $* \" in *\" --check-config \"*) echo config ok; exit 0;; esac\n"
               "while [ \"$1\" != --run-dir ]; do shift; done; run=$2\n"
               "for i in 1 2 3; do\n"
               "  echo \"{\\\"env_steps\\\": $((i * 100)), \\\"wm/recon\\\": $i}\" >> "
               "\"$run/metrics.jsonl\"\n"
               "  echo \"steps $((i * 100))\"; sleep 0.3\n"
               "done\n"
               "cp \"$run/index.html\" \"$run/seen-while-running.html\"\n"
               "exit 0\n";
    std::ofstream actor(bin / "indrive-actor");
    actor << "#!/bin/sh\ncase \" $* \" in *\" --check-config \"*) exit 0;; esac\nexec sleep 30\n";
  }
  std::filesystem::permissions(bin / "indrive-learner", std::filesystem::perms::owner_all);
  std::filesystem::permissions(bin / "indrive-actor", std::filesystem::perms::owner_all);
  std::ofstream(dir.path() / "config.yaml") << "preset: tiny\n";

  LaunchOptions options{.config = dir.path() / "config.yaml",
                        .runs_dir = dir.path() / "runs",
                        .run_id = "paged",
                        .actors = 1,
                        .evaluators = 0,
                        .bin_dir = bin,
                        .status_interval_s = 60.0,
                        .dashboard_interval_s = 0.2};
  EXPECT_EQ(run_launch(options), 0);
  const auto run = dir.path() / "runs" / "paged";
  // What a browser saw meanwhile: a live page that reloads itself.
  const std::string live = testing::slurp(run / "seen-while-running.html");
  EXPECT_NE(live.find("<meta http-equiv=\"refresh\" content=\"1\">"), std::string::npos);
  EXPECT_NE(live.find(">live<"), std::string::npos);
  const std::string page = testing::slurp(run / "index.html");
  EXPECT_NE(page.find("learner exit code 0"), std::string::npos);
  EXPECT_EQ(page.find("http-equiv=\"refresh\""), std::string::npos);  // ended: no more reloads
  EXPECT_NE(page.find("\"title\":\"wm/recon\""), std::string::npos);
  EXPECT_NE(page.find("[1,2,3]"), std::string::npos) << "the three lines of wm/recon";
  const auto status = nlohmann::json::parse(testing::slurp(run / "status.json"));
  EXPECT_EQ(status["state"], "ended");
  EXPECT_EQ(status["processes"][0]["last_line"], "steps 300");

  // --dashboard-interval 0: neither file.
  options.run_id = "unpaged";
  options.dashboard_interval_s = 0.0;
  EXPECT_EQ(run_launch(options), 0);
  EXPECT_FALSE(std::filesystem::exists(dir.path() / "runs" / "unpaged" / "index.html"));
  EXPECT_FALSE(std::filesystem::exists(dir.path() / "runs" / "unpaged" / "status.json"));
}

// Writes an executable stand-in script into `bin`.
void stand_in(const std::filesystem::path& bin, const std::string& name, const std::string& body) {
  std::filesystem::create_directories(bin);
  std::ofstream(bin / name) << "#!/bin/sh\n" << body;
  std::filesystem::permissions(bin / name, std::filesystem::perms::owner_all);
}

// Stand-ins that record every start in <bin>/starts; the evaluator's --check-config runs
// `evaluator_check`.
LaunchOptions recording_launch(const testing::TempDir& dir, const std::string& evaluator_check) {
  const auto bin = dir.path() / "bin";
  const std::string record = "echo \"$*\" >> " + (bin / "starts").string() + "\n";
  stand_in(bin, "indrive-learner",
           record + "case \" $* \" in *\" --check-config \"*) exit 0;; esac\nsleep 1; exit 0\n");
  stand_in(bin, "indrive-actor",
           record + "case \" $* \" in *\" --evaluate \"*\" --check-config \"*) " + evaluator_check +
               ";; *\" --check-config \"*) exit 0;; esac\nexec sleep 30\n");
  std::ofstream(dir.path() / "config.yaml") << "preset: tiny\n";
  return {.config = dir.path() / "config.yaml",
          .runs_dir = dir.path() / "runs",
          .run_id = "r",
          .actors = 2,
          .evaluators = 1,
          .bin_dir = bin,
          .status_interval_s = 60.0,
          .dashboard_interval_s = 0.0};
}

std::vector<std::string> lines_of(const std::filesystem::path& file) {
  std::vector<std::string> lines;
  std::ifstream in(file);
  for (std::string line; std::getline(in, line);) lines.push_back(line);
  return lines;
}

// One role refusing the configuration stops the launch before any process starts: each role is
// checked once (one actor for both), the refusal names the role and carries its message.
TEST(LaunchCheck, ARoleThatRefusesTheConfigurationStopsTheLaunchBeforeAnythingStarts) {
  testing::TempDir dir;
  const LaunchOptions options = recording_launch(
      dir,
      "echo \"2026-12-07 01:00:00.000 E [actor] indrive-actor failed: invalid agent config: "
      "replay.length must be >= 2, got -5\" >&2; exit 1");
  const auto refusal = check_launch_plan(launch_plan(options));
  ASSERT_TRUE(refusal.has_value());
  EXPECT_EQ(*refusal,
            "the evaluator refuses the configuration (exit 1): indrive-actor failed: invalid agent "
            "config: replay.length must be >= 2, got -5");
  EXPECT_EQ(run_launch(options), 2);
  EXPECT_FALSE(std::filesystem::exists(options.runs_dir / "r")) << "nothing made, nothing run";
  const auto starts = lines_of(options.bin_dir / "starts");
  ASSERT_EQ(starts.size(), 6u) << "learner, actor and evaluator checked once, twice over";
  for (const auto& line : starts) EXPECT_NE(line.find("--check-config"), std::string::npos) << line;
}

TEST(LaunchExit, AProcessThatUsedUpItsRestartsFailsTheRunEvenWhenTheLearnerEndedWell) {
  const ChildStatus learner_done{.name = "learner", .state = ChildState::kExited};
  const ChildStatus actor_stopped{
      .name = "actor-0", .state = ChildState::kExited, .last_exit_code = 128 + SIGTERM};
  EXPECT_EQ(launch_exit_code({learner_done, actor_stopped}), 0);
  const ChildStatus evaluator_failed{
      .name = "evaluator-0", .state = ChildState::kFailed, .restarts = 5, .last_exit_code = 3};
  EXPECT_EQ(launch_exit_code({learner_done, actor_stopped, evaluator_failed}), 3);
  // Its own code first: the learner's failure says more than a follower's.
  const ChildStatus learner_failed{
      .name = "learner", .state = ChildState::kFailed, .restarts = 10, .last_exit_code = 1};
  EXPECT_EQ(launch_exit_code({learner_failed, evaluator_failed}), 1);
  // A learner our own SIGTERM stopped (Ctrl-C) ended cleanly.
  const ChildStatus learner_stopped{
      .name = "learner", .state = ChildState::kExited, .last_exit_code = 128 + SIGTERM};
  EXPECT_EQ(launch_exit_code({learner_stopped, actor_stopped}), 0);
  // A process that failed with code 0 (it could not be started again) still fails the run.
  const ChildStatus unstartable{.name = "actor-1", .state = ChildState::kFailed};
  EXPECT_EQ(launch_exit_code({learner_done, unstartable}), 1);
}

}  // namespace
}  // namespace indrive::deploy
