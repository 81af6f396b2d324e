// `indrive`: the project's front door.
//
//   indrive launch --config deploy/configs/smoke.yaml --run-id smoke --actors 2 --evaluators 1
#include <poll.h>
#include <signal.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <cerrno>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <string>
#include <thread>
#include <vector>

#include "indrive/agent/agent.h"
#include "indrive/agent/snapshot_file.h"
#include "indrive/basics/data_path.h"
#include "indrive/basics/log.h"
#include "indrive/basics/run_dir.h"
#include "indrive/deploy/dashboard.h"
#include "indrive/deploy/launch.h"
#include "indrive/deploy/plot.h"
#include "indrive/deploy/report.h"
#include "indrive/deploy/training_episodes.h"
#include "indrive/envserver/town.h"

namespace fs = std::filesystem;

namespace {

// The runs of `indrive compare` and `indrive dashboard`: each positional run its own group, then
// each --group LABEL=RUN[,RUN...], whose runs must be directories.
std::vector<indrive::deploy::CompareGroup> run_groups(const std::vector<fs::path>& runs,
                                                      const std::vector<std::string>& specs) {
  std::vector<indrive::deploy::CompareGroup> groups;
  for (const auto& run : runs) groups.push_back(indrive::deploy::single_run_group(run));
  for (const auto& spec : specs) {
    groups.push_back(indrive::deploy::parse_compare_group(spec));
    for (const auto& run : groups.back().runs) {
      if (!fs::is_directory(run)) {
        throw std::invalid_argument("--group " + spec + ": " + run.string() +
                                    " is not a directory");
      }
    }
  }
  return groups;
}

// The runs of a subcommand that draws several: positional run directories, each its own line,
// and repeatable --group LABEL=RUN[,RUN...] drawn as their mean with a min-max band. run_groups()
// turns them into groups once parsed.
void add_run_options(CLI::App* command, std::vector<fs::path>& runs,
                     std::vector<std::string>& groups, const std::string& group_help) {
  command->add_option("runs", runs, "run directories, each its own line")
      ->check(CLI::ExistingDirectory);
  command->add_option("--group", groups, "LABEL=RUN[,RUN...]: " + group_help + "; repeatable")
      ->expected(1)
      ->allow_extra_args(false)
      ->multi_option_policy(CLI::MultiOptionPolicy::TakeAll);
}

volatile sig_atomic_t g_stop = 0;
void on_stop_signal(int) { g_stop = 1; }

// Standard input read until it ends (`--until-eof`): its last line is what the program feeding
// the page (the learner) says of how the run ended.
class InputEnd {
 public:
  // Whether standard input has reached its end; waits up to `wait_ms` for it.
  bool reached(int wait_ms) {
    pollfd fd{.fd = STDIN_FILENO, .events = POLLIN, .revents = 0};
    if (::poll(&fd, 1, wait_ms) <= 0) return false;
    char buffer[4096];
    const ssize_t n = ::read(STDIN_FILENO, buffer, sizeof buffer);
    if (n < 0) return errno != EINTR && errno != EAGAIN;
    if (n == 0) return true;
    pending_.append(buffer, static_cast<std::size_t>(n));
    for (std::size_t end; (end = pending_.find('\n')) != std::string::npos;) {
      if (end > 0) last_line_ = pending_.substr(0, end);
      pending_.erase(0, end + 1);
    }
    return false;
  }
  std::string last_line() const { return pending_.empty() ? last_line_ : pending_; }

 private:
  std::string pending_, last_line_;
};

// `indrive dashboard`: writes the page once, or with --watch every N seconds until SIGINT or
// SIGTERM, or with --until-eof until standard input ends (the learner's page writer: the
// learner writes how the run ended and closes the pipe, or dies and the pipe closes). For runs
// that no `indrive launch` supervises: docker-compose, several hosts. A single run's coverage
// map is redrawn before each write, as the launcher does.
int run_dashboard(indrive::deploy::DashboardInput input, const fs::path& page, double watch_s,
                  bool until_eof) {
  using indrive::deploy::write_dashboard;
  const auto print = [](const indrive::deploy::DashboardStats& stats) {
    std::printf("%s: %zu charts, %zu points, %zu maps, %zu videos, %.0f KB, written in %.2f s\n",
                stats.page.c_str(), stats.charts, stats.points, stats.pictures, stats.videos,
                stats.bytes / 1024.0, stats.seconds);
    std::fflush(stdout);
  };
  if (watch_s <= 0) {
    print(write_dashboard(input, page));
    return 0;
  }
  struct sigaction action {};
  action.sa_handler = on_stop_signal;
  sigemptyset(&action.sa_mask);
  sigaction(SIGINT, &action, nullptr);
  sigaction(SIGTERM, &action, nullptr);
  const bool one_run = input.runs.size() == 1 && input.runs[0].runs.size() == 1;
  bool warned = false;
  const auto redraw_coverage = [&] {
    if (!one_run) return;
    const fs::path run = input.runs[0].runs[0];
    try {
      indrive::deploy::plot_coverage(run, run / "plots" / "coverage_map.png");
    } catch (const std::exception& error) {
      if (!warned) std::fprintf(stderr, "the coverage map is not redrawn: %s\n", error.what());
      warned = true;
    }
  };
  const std::string ended_text = input.ended;
  input.live_refresh_s = watch_s;
  input.ended.clear();
  indrive::deploy::DashboardCache cache;
  InputEnd input_end;
  bool eof = false;
  while (g_stop == 0 && !eof) {
    redraw_coverage();
    print(write_dashboard(input, page, &cache));
    const auto until = std::chrono::steady_clock::now() + std::chrono::duration<double>(watch_s);
    while (g_stop == 0 && !eof && std::chrono::steady_clock::now() < until) {
      if (until_eof) {
        eof = input_end.reached(100);
      } else {
        std::this_thread::sleep_for(std::chrono::milliseconds(100));
      }
    }
  }
  input.live_refresh_s = 0;
  if (eof) {
    const std::string said = input_end.last_line();
    input.ended = !said.empty() ? said
                                : "ended without a last word from the program feeding this page "
                                  "(the learner was killed or crashed?)";
  } else {
    input.ended = !ended_text.empty() ? ended_text : "watch stopped";
  }
  redraw_coverage();
  print(write_dashboard(input, page, &cache));
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"InDRiVE on SUMO: reward-free world-model pretraining for driving"};
  app.require_subcommand(1);
  std::string log_level = "info";
  app.add_option("--log-level", log_level, "debug, info, warn, error or off");

  indrive::deploy::LaunchOptions launch;
  auto* launch_cmd = app.add_subcommand(
      "launch", "start the learner, actors and evaluators of one run on this host");
  launch_cmd->add_option("--config", launch.config, "run configuration (YAML)")
      ->required()
      ->check(CLI::ExistingFile);
  launch_cmd->add_option("--run-id", launch.run_id, "name of the run (folder under --runs-dir)")
      ->required();
  launch_cmd->add_option("--runs-dir", launch.runs_dir, "where run folders live")
      ->capture_default_str();
  launch_cmd->add_option("--actors", launch.actors, "actor processes")
      ->check(CLI::Range(0, 64))
      ->capture_default_str();
  launch_cmd->add_option("--evaluators", launch.evaluators, "evaluator processes")
      ->check(CLI::Range(0, 64))
      ->capture_default_str();
  launch_cmd->add_option("--domain", launch.domain_id, "DDS domain id")
      ->check(CLI::Range(0, 232))
      ->capture_default_str();
  launch_cmd->add_option("--dds-profile", launch.dds_profile, "Fast DDS XML profiles file")
      ->check(CLI::ExistingFile);
  launch_cmd
      ->add_option("--dds-security", launch.dds_security,
                   "DDS Security folder made by deploy/dds/make_security.sh (default: none)")
      ->check(CLI::ExistingDirectory);
  launch_cmd->add_option("--set", launch.overrides, "config override key=value (repeatable)");
  launch_cmd
      ->add_option("--status-interval", launch.status_interval_s,
                   "seconds between combined status lines")
      ->capture_default_str();
  launch_cmd
      ->add_option("--dashboard-interval", launch.dashboard_interval_s,
                   "seconds between rewrites of the run's page, <run>/index.html (0: none)")
      ->check(CLI::Range(0.0, 86400.0))
      ->capture_default_str();

  std::vector<fs::path> report_inputs;
  fs::path report_out = "report";
  std::string seen_town = "town01";
  std::string heldout_town = "town02";
  auto* report_cmd = app.add_subcommand(
      "report", "write the paper's tables (report.md, report.csv, report.tex) from results");
  report_cmd->add_option("inputs", report_inputs, "run directories, eval folders or CSV files")
      ->required();
  report_cmd->add_option("--out", report_out, "output folder")->capture_default_str();
  report_cmd->add_option("--seen-town", seen_town, "training town for the gap")
      ->capture_default_str();
  report_cmd->add_option("--heldout-town", heldout_town, "held-out town for the gap")
      ->capture_default_str();
  std::string report_route_set = "right";
  report_cmd
      ->add_option("--route-set", report_route_set,
                   "env.route_set the evaluations ran with: the layout bound row is computed on "
                   "the built-in towns' routes of this set")
      ->check(CLI::IsMember(std::vector<std::string>(indrive::env::kRouteSets.begin(),
                                                     indrive::env::kRouteSets.end())))
      ->capture_default_str();

  std::vector<fs::path> episodes_inputs;
  int episodes_last = 5;
  auto* episodes_cmd = app.add_subcommand(
      "episodes",
      "how training went per route, from runs' train-episodes.csv: episodes, SR, route "
      "completion and return per route, over all episodes and the newest --last, and the "
      "return balanced over routes");
  episodes_cmd->add_option("runs", episodes_inputs, "run directories or train-episodes.csv files")
      ->required();
  episodes_cmd->add_option("--last", episodes_last, "newest episodes per route behind last-N")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();

  fs::path plot_run;
  std::string plot_x = "env_steps";
  auto* plot_cmd = app.add_subcommand(
      "plot",
      "draw learning curves (metrics.jsonl, eval/curve-*.csv) and the coverage map of a run "
      "into <run>/plots/");
  plot_cmd->add_option("run", plot_run, "run directory")->required()->check(CLI::ExistingDirectory);
  plot_cmd->add_option("--x", plot_x, "metric on the x axis")->capture_default_str();

  std::vector<fs::path> compare_runs;
  std::string compare_metric;
  fs::path compare_out = "compare.png";
  std::vector<std::string> compare_groups;
  auto* compare_cmd = app.add_subcommand(
      "compare",
      "draw one metric of several runs (metrics.jsonl) into one PNG, a line per run or per "
      "group of runs");
  add_run_options(compare_cmd, compare_runs, compare_groups,
                  "runs drawn as one line, their mean, with a band from the lowest to the "
                  "highest (e.g. the seeds of one method)");
  compare_cmd->add_option("--metric", compare_metric, "metrics.jsonl key, e.g. wm/recon")
      ->required();
  compare_cmd->add_option("--out", compare_out, "PNG to write")->capture_default_str();
  compare_cmd->add_option("--x", plot_x, "metric on the x axis")->capture_default_str();
  double compare_smoothing = 0.0;
  compare_cmd
      ->add_option("--smooth", compare_smoothing,
                   "running-average weight for noisy metrics such as losses (0: none, 0.9: strong)")
      ->check(CLI::Range(0.0, 0.999))
      ->capture_default_str();

  std::vector<fs::path> dashboard_runs;
  std::vector<std::string> dashboard_groups;
  fs::path dashboard_out;
  double dashboard_watch = 0.0;
  indrive::deploy::DashboardInput dashboard;
  auto* dashboard_cmd = app.add_subcommand(
      "dashboard",
      "write one self-contained HTML page (index.html) with the curves, tables, maps, videos, "
      "config and process states of one run or several, overlaid");
  add_run_options(dashboard_cmd, dashboard_runs, dashboard_groups,
                  "runs drawn as their mean with a min-max band (the seeds of one method)");
  dashboard_cmd->add_option(
      "--out", dashboard_out,
      "page to write (default: RUN/index.html for one run; required for several)");
  dashboard_cmd->add_option("--title", dashboard.title, "page title (default: the run labels)");
  dashboard_cmd->add_flag("--videos-first", dashboard.videos_first,
                          "put the evaluation videos above the curves");
  dashboard_cmd
      ->add_option("--watch", dashboard_watch,
                   "rewrite the page every this many seconds until stopped (Ctrl-C); the page "
                   "reloads itself meanwhile")
      ->check(CLI::Range(0.0, 86400.0));
  bool dashboard_until_eof = false;
  dashboard_cmd
      ->add_flag("--until-eof", dashboard_until_eof,
                 "with --watch: also stop when standard input ends, and end the page with the "
                 "last line read from it (how the learner's page writer learns how the run "
                 "ended)")
      ->needs("--watch");
  dashboard_cmd->add_option("--ended", dashboard.ended,
                            "how the run ended, shown at the top of the page (a one-off write, or "
                            "the last one of --watch)");
  dashboard_cmd->add_option("--seen-town", dashboard.seen_town, "training town for the gap")
      ->capture_default_str();
  dashboard_cmd->add_option("--heldout-town", dashboard.heldout_town, "held-out town for the gap")
      ->capture_default_str();

  fs::path snapshot_file;
  fs::path snapshot_acting_out;
  auto* snapshot_cmd = app.add_subcommand(
      "snapshot",
      "say what a snapshot file holds (architecture, groups, sizes); with --acting-only, write "
      "it without the parameters acting does not run (an older file of the whole world model)");
  snapshot_cmd
      ->add_option("file", snapshot_file,
                   "snapshot file (<run>/snapshot.params, "
                   "<run>/eval/snapshot-v<N>.params)")
      ->required()
      ->check(CLI::ExistingFile);
  snapshot_cmd->add_option("--acting-only", snapshot_acting_out,
                           "write the file with only what acting runs (encoder, RSSM, actor) here");

  std::string untrained_preset = "tiny";
  std::uint64_t untrained_seed = 0;
  fs::path untrained_out;
  auto* untrained_cmd = app.add_subcommand(
      "untrained",
      "write the snapshot file of an untrained agent (the initial random parameters of a "
      "preset): the control that shows what evaluations and the route probe give with nothing "
      "learned");
  untrained_cmd->add_option("--preset", untrained_preset, "tiny, small or cpu")
      ->capture_default_str();
  untrained_cmd->add_option("--seed", untrained_seed, "initialisation seed")->capture_default_str();
  untrained_cmd->add_option("--out", untrained_out, "snapshot file to write")->required();

  CLI11_PARSE(app, argc, argv);
  try {
    indrive::log::set_level(indrive::log::parse_level(log_level));
    if (*launch_cmd) {
      launch.bin_dir = indrive::own_program_folder();
      // Before the children start: OpenMP reads these once, when a process loads it.
      indrive::deploy::set_openmp_wait_defaults();
      return indrive::deploy::run_launch(launch);
    }
    if (*dashboard_cmd) {
      if (dashboard_runs.empty() && dashboard_groups.empty()) {
        throw std::invalid_argument("dashboard: name run directories or --group LABEL=RUN,RUN");
      }
      dashboard.runs = run_groups(dashboard_runs, dashboard_groups);
      if (dashboard_out.empty()) {
        if (dashboard_runs.size() != 1 || !dashboard_groups.empty()) {
          throw std::invalid_argument(
              "dashboard: a page over several runs needs --out PAGE.html (one run's page goes "
              "to RUN/index.html)");
        }
        dashboard_out = dashboard_runs[0] / "index.html";
      }
      return run_dashboard(dashboard, dashboard_out, dashboard_watch, dashboard_until_eof);
    }
    if (*plot_cmd) {
      const bool has_metrics = fs::exists(plot_run / "metrics.jsonl");
      if (has_metrics) {
        const auto files =
            indrive::deploy::plot_metrics(plot_run / "metrics.jsonl", plot_run / "plots", plot_x);
        for (const auto& file : files) std::printf("%s\n", file.c_str());
      }
      const auto map =
          indrive::deploy::plot_coverage(plot_run, plot_run / "plots" / "coverage_map.png");
      if (map) std::printf("%s\n", map->c_str());
      const auto curves = indrive::deploy::plot_eval_curves(plot_run, plot_run / "plots");
      for (const auto& file : curves) std::printf("%s\n", file.c_str());
      if (!has_metrics && !map && curves.empty()) {
        throw std::runtime_error(
            plot_run.string() +
            " has no metrics.jsonl, coverage files or eval learning curves: is it a run "
            "directory?");
      }
      return 0;
    }
    if (*compare_cmd) {
      if (compare_runs.empty() && compare_groups.empty()) {
        throw std::invalid_argument("compare: name run directories or --group LABEL=RUN,RUN");
      }
      const auto groups = run_groups(compare_runs, compare_groups);
      const auto ends = indrive::deploy::plot_compare(groups, compare_metric, compare_out, plot_x,
                                                      compare_smoothing);
      std::printf("%s\n", compare_out.c_str());
      // The figures behind the picture, where each line ends.
      for (const auto& end : ends) {
        std::printf("  %-40s %s %.6g: %.6g", end.label.c_str(), plot_x.c_str(), end.x, end.y);
        if (end.low != end.high) std::printf(" (%.6g to %.6g)", end.low, end.high);
        std::printf("\n");
      }
      return 0;
    }
    if (*snapshot_cmd) {
      const auto file = indrive::agent::read_snapshot_file(snapshot_file);
      std::printf("%s: %s", snapshot_file.c_str(),
                  indrive::agent::describe_snapshot_file(file).c_str());
      if (!snapshot_acting_out.empty()) {
        indrive::agent::write_acting_snapshot_file(snapshot_acting_out, file);
        std::printf("%s: %s", snapshot_acting_out.c_str(),
                    indrive::agent::describe_snapshot_file(
                        indrive::agent::read_snapshot_file(snapshot_acting_out))
                        .c_str());
      }
      return 0;
    }
    if (*untrained_cmd) {
      indrive::agent::AgentConfig config = indrive::agent::preset(untrained_preset);
      config.seed = untrained_seed;
      config.replay.seed = untrained_seed;
      const indrive::agent::Agent agent(config);
      indrive::agent::write_snapshot_file(untrained_out, agent.snapshot(), config);
      std::printf(
          "%s: %s", untrained_out.c_str(),
          indrive::agent::describe_snapshot_file(indrive::agent::read_snapshot_file(untrained_out))
              .c_str());
      return 0;
    }
    if (*episodes_cmd) {
      std::vector<indrive::deploy::RunTraining> runs;
      for (const fs::path& input : episodes_inputs) {
        runs.push_back(indrive::deploy::summarize_training(
            indrive::deploy::load_training_episodes(input), episodes_last));
        runs.back().label = input.string();
      }
      std::fputs(indrive::deploy::render_training(runs, episodes_last).c_str(), stdout);
      return 0;
    }
    if (*report_cmd) {
      const auto records = indrive::deploy::load_results(report_inputs);
      const auto report = indrive::deploy::aggregate(records);
      fs::create_directories(report_out);
      indrive::atomic_write(
          report_out / "report.md",
          indrive::deploy::render_markdown(
              report, seen_town, heldout_town,
              indrive::deploy::route_choices_of(report, report_route_set), report_route_set));
      indrive::atomic_write(report_out / "report.csv", indrive::deploy::render_csv(report));
      indrive::atomic_write(report_out / "report.tex", indrive::deploy::render_latex(report));
      std::printf("%d episodes from %zu run(s) -> %s/report.md (.csv, .tex)\n", report.episodes,
                  report.runs.size(), report_out.c_str());
      return 0;
    }
  } catch (const std::exception& error) {
    std::fprintf(stderr, "indrive: %s\n", error.what());
    return 1;
  }
  return 0;
}
