// `indrive dashboard`: one self-contained HTML page of one run or several.
#include <poll.h>
#include <signal.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstdio>
#include <stdexcept>
#include <thread>

#include "command.h"
#include "indrive/deploy/dashboard.h"

namespace indrive::cli {
namespace {

namespace fs = std::filesystem;

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
int run_dashboard(deploy::DashboardInput input, const fs::path& page, double watch_s,
                  bool until_eof) {
  using deploy::write_dashboard;
  const auto print = [](const deploy::DashboardStats& stats) {
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
      deploy::plot_coverage(run, run / "plots" / "coverage_map.png");
    } catch (const std::exception& error) {
      if (!warned) std::fprintf(stderr, "the coverage map is not redrawn: %s\n", error.what());
      warned = true;
    }
  };
  const std::string ended_text = input.ended;
  input.live_refresh_s = watch_s;
  input.ended.clear();
  deploy::DashboardCache cache;
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

class DashboardCommand final : public Command {
 public:
  CLI::App* add_to(CLI::App& app) override {
    auto* command = app.add_subcommand(
        "dashboard",
        "write one self-contained HTML page (index.html) with the curves, tables, maps, videos, "
        "config and process states of one run or several, overlaid");
    runs_.add_to(command, "runs drawn as their mean with a min-max band (the seeds of one method)");
    command->add_option(
        "--out", out_, "page to write (default: RUN/index.html for one run; required for several)");
    command->add_option("--title", input_.title, "page title (default: the run labels)");
    command->add_flag("--videos-first", input_.videos_first,
                      "put the evaluation videos above the curves");
    command
        ->add_option("--watch", watch_s_,
                     "rewrite the page every this many seconds until stopped (Ctrl-C); the page "
                     "reloads itself meanwhile")
        ->check(CLI::Range(0.0, 86400.0));
    command
        ->add_flag("--until-eof", until_eof_,
                   "with --watch: also stop when standard input ends, and end the page with the "
                   "last line read from it (how the learner's page writer learns how the run "
                   "ended)")
        ->needs("--watch");
    command->add_option("--ended", input_.ended,
                        "how the run ended, shown at the top of the page (a one-off write, or "
                        "the last one of --watch)");
    command->add_option("--seen-town", input_.seen_town, "training town for the gap")
        ->capture_default_str();
    command->add_option("--heldout-town", input_.heldout_town, "held-out town for the gap")
        ->capture_default_str();
    return command;
  }

  int run() override {
    if (runs_.empty()) {
      throw std::invalid_argument("dashboard: name run directories or --group LABEL=RUN,RUN");
    }
    input_.runs = runs_.parse();
    if (out_.empty()) {
      if (runs_.runs.size() != 1 || !runs_.groups.empty()) {
        throw std::invalid_argument(
            "dashboard: a page over several runs needs --out PAGE.html (one run's page goes to "
            "RUN/index.html)");
      }
      out_ = runs_.runs[0] / "index.html";
    }
    return run_dashboard(input_, out_, watch_s_, until_eof_);
  }

 private:
  RunOptions runs_;
  fs::path out_;
  double watch_s_ = 0.0;
  bool until_eof_ = false;
  deploy::DashboardInput input_;
};

}  // namespace

std::unique_ptr<Command> dashboard_command() { return std::make_unique<DashboardCommand>(); }

}  // namespace indrive::cli
