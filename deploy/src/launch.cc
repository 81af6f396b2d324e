#include "indrive/deploy/launch.h"

#include <signal.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <nlohmann/json.hpp>
#include <optional>
#include <set>
#include <sstream>

#include "indrive/basics/log.h"
#include "indrive/basics/run_dir.h"
#include "indrive/dds/shm_sweeper.h"
#include "indrive/deploy/dashboard.h"
#include "indrive/deploy/plot.h"

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

// The run's page, refreshed while it runs; a failure to write it is logged once and never
// stops the run.
class PageRefresher {
 public:
  PageRefresher(const LaunchOptions& options, fs::path run_dir)
      : interval_s_(options.dashboard_interval_s), run_dir_(std::move(run_dir)) {
    input_.runs = {single_run_group(run_dir_)};
    input_.title = options.run_id;
  }

  bool enabled() const { return interval_s_ > 0; }

  void refresh(const std::vector<ChildStatus>& processes, bool ended, const std::string& why) {
    if (!enabled()) return;
    const auto start = std::chrono::steady_clock::now();
    try {
      write_status_json(run_dir_, processes, ended);
      // The coverage map is redrawn from the actors' coverage files (none before they step).
      plot_coverage(run_dir_, run_dir_ / "plots" / "coverage_map.png");
      input_.live_refresh_s = ended ? 0.0 : interval_s_;
      input_.ended = ended ? why : "";
      const DashboardStats stats = write_dashboard(input_, run_dir_ / "index.html", &cache_);
      bytes_ = stats.bytes;
    } catch (const std::exception& error) {
      if (!warned_) {
        INDRIVE_LOG(kWarn, "launch") << "the run's page was not written: " << error.what();
        warned_ = true;
      }
    }
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    ++writes_;
    total_s_ += seconds;
    max_s_ = std::max(max_s_, seconds);
  }

  // "page: <run>/index.html (N writes, mean X s, max Y s, Z KB)"
  std::string summary() const {
    std::ostringstream text;
    text.precision(3);
    text << "page: " << (run_dir_ / "index.html").string() << " (" << writes_ << " writes, mean "
         << (writes_ > 0 ? total_s_ / writes_ : 0.0) << " s, max " << max_s_ << " s, "
         << bytes_ / 1024 << " KB)";
    return text.str();
  }

 private:
  double interval_s_;
  fs::path run_dir_;
  DashboardInput input_;
  DashboardCache cache_;  // each write reads only the metrics lines appended since the last
  bool warned_ = false;
  int writes_ = 0;
  double total_s_ = 0.0, max_s_ = 0.0;
  std::size_t bytes_ = 0;
};

}  // namespace

void write_status_json(const fs::path& run_dir, const std::vector<ChildStatus>& processes,
                       bool ended) {
  nlohmann::json status = {{"written", local_time_now()},
                           {"state", ended ? "ended" : "running"},
                           {"processes", nlohmann::json::array()}};
  for (const auto& p : processes) {
    status["processes"].push_back({{"name", p.name},
                                   {"state", child_state_name(p.state)},
                                   {"pid", p.pid},
                                   {"restarts", p.restarts},
                                   {"last_exit_code", p.last_exit_code},
                                   {"last_line", p.last_line}});
  }
  atomic_write(run_dir / "status.json", status.dump(2) + "\n");
}

std::vector<ProcessSpec> launch_plan(const LaunchOptions& options) {
  const fs::path run_dir = options.runs_dir / options.run_id;
  const fs::path logs = run_dir / "logs";
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
  // The launcher writes the page itself (with every process's state): the learner's own page
  // writer stays off, whatever the overrides say.
  learner.argv.insert(learner.argv.end(), {"--set", "learner.dashboard_s=0"});
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

void set_openmp_wait_defaults() {
  // Spinning threads measured a 17x slower learner on 2 cores beside its actors (the service
  // benchmark). Sleeping at once costs an update's many parallel regions a wake-up each: the tiny
  // update with 2 threads took 0.046-0.058 s so and 0.042-0.053 s with a 10k-iteration spin first
  // (libgomp's default spin is 300k, passive's 0), in alternating runs on a noisy 2-core machine.
  // Since actors sleep until their allowance comes (actor::AllowanceGate) instead of polling, a
  // 100k spin did better again: tiny at ratio 32 with 1 actor, 90.3 / 88.3 / 89.5 / 76.0 / 82.0
  // env steps/s against 90.0 / 81.9 / 79.7 / 69.3 / 75.7 with 10k (alternating; 2 actors: even).
  ::setenv("OMP_WAIT_POLICY", "passive", /*overwrite=*/0);
  ::setenv("GOMP_SPINCOUNT", "100000", /*overwrite=*/0);
}

int launch_exit_code(const std::vector<ChildStatus>& processes) {
  int exit_code = 0;
  for (const auto& status : processes) {
    if (status.name == "learner") {
      // A learner stopped by our own SIGTERM counts as a clean stop.
      exit_code = status.last_exit_code == 128 + SIGTERM ? 0 : status.last_exit_code;
    }
  }
  // A process that used up its restarts failed the run too, even when the learner ended well.
  for (const auto& status : processes) {
    if (exit_code == 0 && status.state == ChildState::kFailed) {
      exit_code = status.last_exit_code != 0 ? status.last_exit_code : 1;
    }
  }
  return exit_code;
}

std::optional<std::string> check_launch_plan(const std::vector<ProcessSpec>& plan,
                                             std::chrono::seconds limit) {
  Supervisor checks;
  std::set<std::string> roles;
  for (const auto& spec : plan) {
    // "actor-1" and "evaluator-0" have the roles "actor" and "evaluator": one check each.
    const std::string role = spec.name.substr(0, spec.name.find('-'));
    if (!roles.insert(role).second) continue;
    ProcessSpec check{.name = role, .argv = spec.argv, .restart = RestartPolicy::kNever};
    check.argv.push_back("--check-config");
    checks.add(std::move(check));
  }
  std::map<std::string, std::string> last_line;
  checks.on_line([&](const std::string& name, const std::string& line) {
    if (!line.empty()) last_line[name] = line;
  });
  checks.start();
  const auto deadline = std::chrono::steady_clock::now() + limit;
  while (checks.poll(std::chrono::milliseconds(50))) {
    if (std::chrono::steady_clock::now() > deadline) {
      checks.stop(std::chrono::seconds(2));
      return "the configuration checks did not finish within " + std::to_string(limit.count()) +
             " s";
    }
  }
  for (const auto& status : checks.status()) {
    if (status.last_exit_code == 0) continue;
    std::string message = last_line[status.name];
    // The programs' log lines start "<date> <time> E [role] "; the message is what follows.
    if (const auto bracket = message.find("] "); bracket != std::string::npos) {
      message = message.substr(bracket + 2);
    }
    return "the " + status.name + " refuses the configuration (exit " +
           std::to_string(status.last_exit_code) + "): " + message;
  }
  return std::nullopt;
}

int run_launch(const LaunchOptions& options) {
  auto plan = launch_plan(options);
  // Every role checks the configuration the way it will read it, before anything starts: a
  // typo is refused in about a second instead of after a round of restarts.
  if (const auto refusal = check_launch_plan(plan)) {
    std::fprintf(stderr,
                 "launch: %s\nlaunch: nothing was started; fix the config or the --set "
                 "override and launch again\n",
                 refusal->c_str());
    return 2;
  }
  fs::create_directories(options.runs_dir / options.run_id / "logs");
  Supervisor supervisor;
  for (auto& spec : plan) supervisor.add(std::move(spec));
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
  const fs::path run_dir = options.runs_dir / options.run_id;
  PageRefresher page(options, run_dir);
  if (page.enabled()) {
    std::printf("%-12s | the run's page: %s (refreshed every %g s; open it in a browser)\n",
                "launch", (run_dir / "index.html").c_str(), options.dashboard_interval_s);
  }
  auto next_status = std::chrono::steady_clock::now();
  auto next_page = next_status;
  // A process that ends by a signal leaves its Fast DDS shared-memory segment in /dev/shm
  // (about 23 MiB each with single_host.xml); the launcher, which restarts such processes, removes
  // them once they are surely dead (dds/shm_sweeper.h), every minute.
  std::optional<dds::SharedMemorySweeper> sweeper;
  if (fs::is_directory("/dev/shm")) sweeper.emplace("/dev/shm");
  auto next_sweep = next_status;
  while (supervisor.poll(std::chrono::milliseconds(200))) {
    const auto now = std::chrono::steady_clock::now();
    if (sweeper && now >= next_sweep) {
      next_sweep = now + std::chrono::seconds(60);
      const auto swept = sweeper->sweep(now);
      if (swept.removed > 0) {
        std::printf("%-12s | removed %d shared-memory segment(s) of ended processes (%.1f MiB)\n",
                    "launch", swept.removed, static_cast<double>(swept.removed_bytes) / (1 << 20));
        std::fflush(stdout);
      }
    }
    if (page.enabled() && now >= next_page) {
      page.refresh(supervisor.status(), /*ended=*/false, "");
      next_page = std::chrono::steady_clock::now() +
                  std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                      std::chrono::duration<double>(options.dashboard_interval_s));
    }
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
    if (status.state != ChildState::kFailed) continue;
    std::printf("%-12s | %s failed for good: exit code %d after %d restart(s)\n", "launch",
                status.name.c_str(), status.last_exit_code, status.restarts);
  }
  const int exit_code = launch_exit_code(supervisor.status());
  if (page.enabled()) {
    page.refresh(supervisor.status(), /*ended=*/true,
                 "ended " + local_time_now() + ", learner exit code " + std::to_string(exit_code));
    std::printf("%-12s | %s\n", "launch", page.summary().c_str());
  }
  const fs::path final_snapshot = final_snapshot_path(run_dir);
  if (fs::exists(final_snapshot)) {
    std::printf(
        "%-12s | the run's final policy: %s (indrive-actor --evaluate --snapshot FILE evaluates "
        "it again, with no config)\n",
        "launch", final_snapshot.c_str());
  }
  return exit_code;
}

}  // namespace indrive::deploy
