// The run's page (index.html, see `indrive dashboard`) kept fresh by a learner that runs without
// `indrive launch` (docker-compose, several hosts): a companion `indrive dashboard --watch S
// --until-eof` process beside the learner, fed through a pipe on its standard input.
//
//   PageWriter page(bin_dir / "indrive", run_dir, 30.0);  // starts the writer (or logs why not)
//   ... the learner runs ...
//   page.finish("budget reached, learner exit code 0");   // the page's last words, then waits
//
// The page is written by another process so that the learner links no report or plotting code
// and a failing page write can never stop training. The pipe carries the end of the run: the
// learner writes one line and closes it; a learner that crashes or is killed closes it too, and
// the writer then says the learner ended without a word. The learner's own cost is the start
// and this line; the writer's CPU time is measured and logged at the end.
#pragma once

#include <sys/types.h>

#include <cstdint>
#include <filesystem>
#include <string>

namespace indrive::learner {

class PageWriter {
 public:
  // Starts `program` (indrive) as `program dashboard RUN_DIR --watch interval_s --until-eof`
  // with its output appended to RUN_DIR/logs/dashboard.log. A program that is missing or does
  // not start leaves the writer off with one warning that says what to do; never throws.
  PageWriter(const std::filesystem::path& program, const std::filesystem::path& run_dir,
             double interval_s);
  // Same as finish("ended: the program stopped without saying how").
  ~PageWriter();
  PageWriter(const PageWriter&) = delete;
  PageWriter& operator=(const PageWriter&) = delete;

  bool running() const { return pid_ > 0; }
  pid_t pid() const { return pid_; }

  // Hands the writer the run's last words (one line) and waits up to `wait_s` seconds for its
  // final page; then logs the page path and the writer's CPU time against the wall time since
  // the start. Returns whether the writer exited with 0 in time. Only the first call counts.
  bool finish(const std::string& how_it_ended, double wait_s = 60.0);

  // CPU seconds (user + system) of the writer, known after finish() reaped it; -1 before.
  double cpu_seconds() const { return cpu_s_; }
  double wall_seconds() const { return wall_s_; }

 private:
  std::filesystem::path page_;
  pid_t pid_ = -1;
  int pipe_ = -1;  // write end; the writer's standard input
  double start_s_ = 0.0;
  double cpu_s_ = -1.0;
  double wall_s_ = 0.0;
  bool finished_ = false;
};

// The last words of a training program's page: "ended: budget reached at N env steps and M
// updates, <program> exit code C" (or "stopped by a signal").
std::string training_ended(bool stopped, std::int64_t env_steps, std::int64_t updates,
                           const std::string& program, int exit_code);

}  // namespace indrive::learner
