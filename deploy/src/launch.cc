#include "indrive/deploy/launch.h"

#include <signal.h>

#include <chrono>
#include <cstdio>
#include <sstream>

#include "indrive/basics/log.h"

namespace indrive::deploy {
namespace fs = std::filesystem;

namespace {

Supervisor* g_supervisor = nullptr;

void on_signal(int) {
  if (g_supervisor != nullptr) g_supervisor->request_stop();
}

std::vector<std::string> common_args(const LaunchOptions& options, const fs::path& run_dir) {
  std::vector<std::string> args = {"--config",  options.config.string(),
                                   "--run-dir", run_dir.string(),
                                   "--domain",  std::to_string(options.domain_id)};
  if (!options.dds_profile.empty()) {
    args.insert(args.end(), {"--dds-profile", options.dds_profile.string()});
  }
  // Every process gets the same folder and picks its own role's files from it.
  if (!options.dds_security.empty()) {
    args.insert(args.end(), {"--dds-security", options.dds_security.string()});
  }
  for (const auto& override_text : options.overrides) {
    args.insert(args.end(), {"--set", override_text});
  }
  return args;
}

}  // namespace

std::vector<ProcessSpec> launch_plan(const LaunchOptions& options) {
  const fs::path run_dir = options.runs_dir / options.run_id;
  const fs::path logs = run_dir / "logs";
  fs::create_directories(logs);
  const auto args = common_args(options, run_dir);
  std::vector<ProcessSpec> plan;

  // A crashed learner is restarted too: it resumes from its newest checkpoint while the actors
  // wait at their allowance. A clean exit (budget reached, stopped) ends the run.
  ProcessSpec learner{
      .name = "learner",
      .restart = RestartPolicy::kOnFailure,
      .backoff = {.initial_s = 1.0, .factor = 2.0, .max_s = 30.0, .max_restarts = 10},
      .essential = true,
      .log_file = logs / "learner.log"};
  learner.argv = {(options.bin_dir / "indrive-learner").string()};
  learner.argv.insert(learner.argv.end(), args.begin(), args.end());
  plan.push_back(std::move(learner));

  for (int i = 0; i < options.actors; ++i) {
    const std::string name = "actor-" + std::to_string(i);
    ProcessSpec actor{.name = name,
                      .restart = RestartPolicy::kOnFailure,
                      .backoff = {.initial_s = 1.0, .factor = 2.0, .max_s = 30.0},
                      .log_file = logs / (name + ".log")};
    actor.argv = {(options.bin_dir / "indrive-actor").string()};
    actor.argv.insert(actor.argv.end(), args.begin(), args.end());
    actor.argv.insert(actor.argv.end(), {"--id", std::to_string(i)});
    plan.push_back(std::move(actor));
  }
  for (int j = 0; j < options.evaluators; ++j) {
    const std::string name = "evaluator-" + std::to_string(j);
    ProcessSpec evaluator{
        .name = name,
        .restart = RestartPolicy::kOnFailure,
        .backoff = {.initial_s = 1.0, .factor = 2.0, .max_s = 30.0, .max_restarts = 5},
        // It evaluates the learner's final snapshot after the learner has ended the run.
        .finishes_run = true,
        .log_file = logs / (name + ".log")};
    evaluator.argv = {(options.bin_dir / "indrive-actor").string(), "--evaluate"};
    evaluator.argv.insert(evaluator.argv.end(), args.begin(), args.end());
    evaluator.argv.insert(evaluator.argv.end(),
                          {"--id", std::to_string(j), "--of", std::to_string(options.evaluators)});
    plan.push_back(std::move(evaluator));
  }
  return plan;
}

int run_launch(const LaunchOptions& options) {
  Supervisor supervisor;
  for (auto& spec : launch_plan(options)) supervisor.add(std::move(spec));
  supervisor.on_line([](const std::string& name, const std::string& line) {
    std::printf("%-12s | %s\n", name.c_str(), line.c_str());
    std::fflush(stdout);
  });

  g_supervisor = &supervisor;
  struct sigaction action {};
  action.sa_handler = on_signal;
  sigemptyset(&action.sa_mask);
  sigaction(SIGINT, &action, nullptr);
  sigaction(SIGTERM, &action, nullptr);

  supervisor.start();
  auto next_status = std::chrono::steady_clock::now();
  while (supervisor.poll(std::chrono::milliseconds(200))) {
    const auto now = std::chrono::steady_clock::now();
    if (now < next_status) continue;
    next_status = now + std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                            std::chrono::duration<double>(options.status_interval_s));
    std::ostringstream line;
    for (const auto& status : supervisor.status()) {
      line << status.name << "=" << child_state_name(status.state);
      if (status.restarts > 0) line << "(restarts " << status.restarts << ")";
      line << " ";
    }
    std::printf("%-12s | %s\n", "launch", line.str().c_str());
    std::fflush(stdout);
  }
  std::printf("%-12s | stopping all processes\n", "launch");
  supervisor.stop(std::chrono::seconds(15));
  g_supervisor = nullptr;
  for (const auto& status : supervisor.status()) {
    if (status.name == "learner") {
      // A learner stopped by our own SIGTERM counts as a clean stop.
      return status.last_exit_code == 128 + SIGTERM ? 0 : status.last_exit_code;
    }
  }
  return 0;
}

}  // namespace indrive::deploy
