// `indrive launch`: the processes of one training run on this host.
//
// Builds the process list (learner, N actors, M evaluators) for a config and a run directory,
// and runs it under a Supervisor with a combined progress view.
#pragma once

#include <chrono>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "indrive/deploy/supervisor.h"

namespace indrive::deploy {

struct LaunchOptions {
  std::filesystem::path config;  // YAML config given to every process
  std::filesystem::path runs_dir = "runs";
  std::string run_id;
  int actors = 2;
  int evaluators = 1;
  int domain_id = 0;
  std::filesystem::path dds_profile;   // XML profiles file; empty: the processes' default
  std::filesystem::path dds_security;  // DDS Security folder (make_security.sh); empty: off
  std::vector<std::string> overrides;  // --set key=value, forwarded to every process
  std::filesystem::path bin_dir;       // where indrive-learner and indrive-actor live
  double status_interval_s = 10.0;     // how often the combined status line is printed
  // How often <run>/status.json and the run's page, <run>/index.html (indrive dashboard), are
  // rewritten while the run goes on; 0: neither is written.
  double dashboard_interval_s = 30.0;
};

// <run>/status.json: the time, "running" or "ended", and each process's state, restarts, last
// exit code and newest output line, as the run's page shows them.
void write_status_json(const std::filesystem::path& run_dir,
                       const std::vector<ChildStatus>& processes, bool ended);

// The process specs for `options`: the learner (essential: its clean exit ends the run; a crash
// is restarted with back-off, at most 10 times), actors restarted on failure with back-off,
// evaluators restarted at most 5 times. Output of each goes to <run>/logs/<name>.log too.
// Creates nothing.
std::vector<ProcessSpec> launch_plan(const LaunchOptions& options);

// Runs each role of `plan` once (learner, actor, evaluator) with --check-config, side by side,
// and waits up to `limit`. Returns the first refusal, "the <role> refuses the configuration
// (exit N): <its message>", or nothing when every role accepts it.
std::optional<std::string> check_launch_plan(const std::vector<ProcessSpec>& plan,
                                             std::chrono::seconds limit = std::chrono::seconds(60));

// Sets, for the children started afterwards, how idle OpenMP threads wait, unless the
// environment already says: OMP_WAIT_POLICY=passive (the processes share the cores; spinning
// threads would take them from each other) and GOMP_SPINCOUNT=100000 (libgomp spins that many
// iterations before sleeping, so an update's back-to-back parallel regions do not each wake
// threads through the kernel). OpenMP reads both once, when a process loads it.
void set_openmp_wait_defaults();

// The launch's exit code from its processes' last states: the learner's (0 when our SIGTERM
// stopped it); when that is 0, the first process that failed for good (used up its restarts)
// gives its exit code (1 if it was 0).
int launch_exit_code(const std::vector<ChildStatus>& processes);

// Checks the plan's configuration (check_launch_plan) and returns 2 with the refusal on stderr
// when a role refuses it, before anything starts or any folder is made. Otherwise runs the plan
// until the learner ends or SIGINT/SIGTERM arrives, then stops everything.
// Meanwhile refreshes the run's page every dashboard_interval_s (the coverage map redrawn, the
// page reloading itself) and writes it a last time when the run has ended; prints its path.
// Returns launch_exit_code().
int run_launch(const LaunchOptions& options);

}  // namespace indrive::deploy
