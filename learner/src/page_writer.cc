#include "indrive/learner/page_writer.h"

#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstring>
#include <sstream>
#include <thread>
#include <vector>

#include "indrive/basics/child_signals.h"
#include "indrive/basics/log.h"

extern char** environ;

namespace indrive::learner {
namespace fs = std::filesystem;
namespace {

double now_s() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

std::string number_text(double value) {
  std::ostringstream text;
  text << value;
  return text.str();
}

}  // namespace

PageWriter::PageWriter(const fs::path& program, const fs::path& run_dir, double interval_s)
    : page_(run_dir / "index.html"), start_s_(now_s()) {
  if (interval_s <= 0) return;
  if (::access(program.c_str(), X_OK) != 0) {
    INDRIVE_LOG(kWarn, "learner")
        << "the run's page is not kept: " << program.string()
        << " is missing (install the indrive program beside indrive-learner, or set "
           "learner.dashboard_s=0 to silence this)";
    return;
  }
  std::error_code error;
  fs::create_directories(run_dir / "logs", error);
  int fds[2];
  if (::pipe2(fds, O_CLOEXEC) != 0) {
    INDRIVE_LOG(kWarn, "learner") << "the run's page is not kept: pipe: " << std::strerror(errno);
    return;
  }
  // A writer that died must not take the learner with it when the last line is written.
  ::signal(SIGPIPE, SIG_IGN);
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_adddup2(&actions, fds[0], STDIN_FILENO);
  const std::string log = (run_dir / "logs" / "dashboard.log").string();
  posix_spawn_file_actions_addopen(&actions, STDOUT_FILENO, log.c_str(),
                                   O_WRONLY | O_CREAT | O_APPEND, 0644);
  posix_spawn_file_actions_adddup2(&actions, STDOUT_FILENO, STDERR_FILENO);
  std::vector<std::string> args = {program.string(),        "dashboard",
                                   run_dir.string(),        "--watch",
                                   number_text(interval_s), "--until-eof"};
  std::vector<char*> argv;
  argv.reserve(args.size() + 1);
  for (auto& arg : args) argv.push_back(arg.data());
  argv.push_back(nullptr);
  pid_t pid = -1;
  // The learner blocks its stop signals outside their own thread: the writer gets them back.
  const ChildSignals child_signals;
  const int failed = ::posix_spawn(&pid, program.c_str(), &actions, child_signals.attributes(),
                                   argv.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  ::close(fds[0]);
  if (failed != 0) {
    ::close(fds[1]);
    INDRIVE_LOG(kWarn, "learner") << "the run's page is not kept: " << program.string()
                                  << " did not start: " << std::strerror(failed);
    return;
  }
  pid_ = pid;
  pipe_ = fds[1];
  INDRIVE_LOG(kInfo, "learner") << "the run's page " << page_.string() << " is rewritten every "
                                << interval_s << " s by indrive dashboard (pid " << pid_ << ", log "
                                << log << ")";
}

PageWriter::~PageWriter() { finish("ended: the program stopped without saying how", 10.0); }

bool PageWriter::finish(const std::string& how_it_ended, double wait_s) {
  if (finished_ || pid_ <= 0) return false;
  finished_ = true;
  std::string line = how_it_ended;
  for (char& c : line) {
    if (c == '\n' || c == '\r') c = ' ';
  }
  line += '\n';
  // A short line into an empty pipe is written whole; a writer already gone gives EPIPE, which
  // the reaping below reports.
  [[maybe_unused]] const ssize_t written = ::write(pipe_, line.data(), line.size());
  ::close(pipe_);
  pipe_ = -1;

  const double deadline = now_s() + wait_s;
  int status = 0;
  rusage usage{};
  pid_t reaped = 0;
  while ((reaped = ::wait4(pid_, &status, WNOHANG, &usage)) == 0 && now_s() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  wall_s_ = now_s() - start_s_;
  if (reaped != pid_) {
    INDRIVE_LOG(kWarn, "learner") << "the page writer (pid " << pid_ << ") has not finished "
                                  << page_.string() << " after " << wait_s
                                  << " s; it is left to finish alone";
    return false;
  }
  cpu_s_ = static_cast<double>(usage.ru_utime.tv_sec + usage.ru_stime.tv_sec) +
           1e-6 * static_cast<double>(usage.ru_utime.tv_usec + usage.ru_stime.tv_usec);
  const bool ok = WIFEXITED(status) && WEXITSTATUS(status) == 0;
  if (!ok) {
    INDRIVE_LOG(kWarn, "learner") << "the page writer (pid " << pid_ << ") ended with "
                                  << (WIFEXITED(status)
                                          ? "exit code " + std::to_string(WEXITSTATUS(status))
                                          : "signal " + std::to_string(WTERMSIG(status)))
                                  << "; see "
                                  << (page_.parent_path() / "logs" / "dashboard.log").string();
  }
  INDRIVE_LOG(kInfo, "learner") << "page: " << page_.string() << " (its writer used " << cpu_s_
                                << " s of CPU over " << wall_s_ << " s, "
                                << (wall_s_ > 0 ? 100.0 * cpu_s_ / wall_s_ : 0.0)
                                << "% of one core)";
  pid_ = -1;
  return ok;
}

std::string training_ended(bool stopped, std::int64_t env_steps, std::int64_t updates,
                           const std::string& program, int exit_code) {
  std::ostringstream text;
  text << "ended: " << (stopped ? "stopped by a signal" : "budget reached") << " at " << env_steps
       << " env steps and " << updates << " updates, " << program << " exit code " << exit_code;
  return text.str();
}

}  // namespace indrive::learner
