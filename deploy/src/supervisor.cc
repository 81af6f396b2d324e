#include "indrive/deploy/supervisor.h"

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <fstream>
#include <thread>

#include "indrive/basics/child_signals.h"
#include "indrive/basics/log.h"

namespace indrive::deploy {

using Clock = std::chrono::steady_clock;

struct Supervisor::Child {
  ProcessSpec spec;
  ChildStatus status;
  int output_fd = -1;
  std::string partial;  // output bytes after the last newline
  Clock::time_point started_at{};
  Clock::time_point restart_at{};
  int consecutive_failures = 0;
  std::ofstream log;
};

const char* child_state_name(ChildState state) {
  switch (state) {
    case ChildState::kPending:
      return "pending";
    case ChildState::kRunning:
      return "running";
    case ChildState::kWaitingRestart:
      return "restarting";
    case ChildState::kExited:
      return "exited";
    case ChildState::kFailed:
      return "failed";
  }
  return "?";
}

Supervisor::Supervisor() = default;

Supervisor::~Supervisor() {
  stop(std::chrono::seconds(5));
  for (Child* child : children_) delete child;
}

void Supervisor::add(ProcessSpec spec) {
  if (spec.argv.empty()) throw LaunchError("process '" + spec.name + "' has an empty command");
  auto* child = new Child;
  child->status.name = spec.name;
  if (!spec.log_file.empty()) {
    child->log.open(spec.log_file, std::ios::app);
    if (!child->log) {
      delete child;
      throw LaunchError("cannot open log file " + spec.log_file.string() + " for process '" +
                        spec.name + "'");
    }
  }
  child->spec = std::move(spec);
  children_.push_back(child);
}

void Supervisor::on_line(std::function<void(const std::string&, const std::string&)> callback) {
  on_line_ = std::move(callback);
}

void Supervisor::start() {
  for (Child* child : children_) spawn(*child);
}

void Supervisor::spawn(Child& child) {
  int fds[2];
  if (::pipe2(fds, O_CLOEXEC) != 0) {
    throw LaunchError("cannot create a pipe for '" + child.spec.name +
                      "': " + std::strerror(errno));
  }
  // An exec failure is reported through a second close-on-exec pipe: if exec succeeds the
  // pipe closes empty, otherwise the child writes errno into it.
  int exec_fds[2];
  if (::pipe2(exec_fds, O_CLOEXEC) != 0) {
    ::close(fds[0]);
    ::close(fds[1]);
    throw LaunchError("cannot create a pipe: " + std::string(std::strerror(errno)));
  }
  const pid_t parent = ::getpid();
  const pid_t pid = ::fork();
  if (pid < 0) {
    throw LaunchError("cannot fork for '" + child.spec.name + "': " + std::strerror(errno));
  }
  if (pid == 0) {
    // Child: own process group (the launcher forwards terminal signals itself), die with the
    // launcher, stdout and stderr into the pipe.
    ::setpgid(0, 0);
    reset_signals_for_exec();  // nothing blocked or ignored is passed on
    ::prctl(PR_SET_PDEATHSIG, SIGTERM);
    if (::getppid() != parent) ::_exit(127);
    ::dup2(fds[1], STDOUT_FILENO);
    ::dup2(fds[1], STDERR_FILENO);
    for (const auto& [key, value] : child.spec.env) ::setenv(key.c_str(), value.c_str(), 1);
    std::vector<char*> argv;
    for (auto& arg : child.spec.argv) argv.push_back(arg.data());
    argv.push_back(nullptr);
    ::execvp(argv[0], argv.data());
    const int error = errno;
    [[maybe_unused]] auto written = ::write(exec_fds[1], &error, sizeof error);
    ::_exit(127);
  }
  // Also set the group from the parent, so a signal sent right after fork reaches the group.
  ::setpgid(pid, pid);
  ::close(fds[1]);
  ::close(exec_fds[1]);
  int exec_error = 0;
  const auto got = ::read(exec_fds[0], &exec_error, sizeof exec_error);
  ::close(exec_fds[0]);
  if (got == static_cast<ssize_t>(sizeof exec_error)) {
    ::close(fds[0]);
    ::waitpid(pid, nullptr, 0);
    throw LaunchError("cannot start '" + child.spec.name + "' (" + child.spec.argv[0] +
                      "): " + std::strerror(exec_error) +
                      "; is the project built (bash deploy/setup.sh build)?");
  }
  ::fcntl(fds[0], F_SETFL, ::fcntl(fds[0], F_GETFL) | O_NONBLOCK);
  child.output_fd = fds[0];
  child.partial.clear();
  child.status.pid = pid;
  child.status.state = ChildState::kRunning;
  child.started_at = Clock::now();
  INDRIVE_LOG(kInfo, "launch") << "started " << child.spec.name << " (pid " << pid << ")";
}

void Supervisor::emit(Child& child, const std::string& line) {
  child.status.last_line = line;
  if (child.log.is_open()) child.log << line << '\n' << std::flush;
  if (on_line_) on_line_(child.spec.name, line);
}

void Supervisor::pump_output(std::chrono::milliseconds wait) {
  std::vector<pollfd> fds;
  std::vector<Child*> owners;
  for (Child* child : children_) {
    if (child->output_fd >= 0) {
      fds.push_back({child->output_fd, POLLIN, 0});
      owners.push_back(child);
    }
  }
  if (fds.empty()) {
    std::this_thread::sleep_for(wait);
    return;
  }
  if (::poll(fds.data(), fds.size(), static_cast<int>(wait.count())) <= 0) return;
  char buffer[65536];
  for (std::size_t i = 0; i < fds.size(); ++i) {
    if (!(fds[i].revents & (POLLIN | POLLHUP | POLLERR))) continue;
    Child& child = *owners[i];
    for (;;) {
      const ssize_t n = ::read(child.output_fd, buffer, sizeof buffer);
      if (n > 0) {
        child.partial.append(buffer, static_cast<std::size_t>(n));
        std::size_t newline;
        while ((newline = child.partial.find('\n')) != std::string::npos) {
          emit(child, child.partial.substr(0, newline));
          child.partial.erase(0, newline + 1);
        }
        continue;
      }
      if (n == 0) {  // writer closed: the child is gone or closed its output
        if (!child.partial.empty()) emit(child, child.partial);
        child.partial.clear();
        ::close(child.output_fd);
        child.output_fd = -1;
      }
      break;  // EAGAIN: nothing more for now
    }
  }
}

void Supervisor::reap() {
  const auto now = Clock::now();
  for (Child* child_ptr : children_) {
    Child& child = *child_ptr;
    if (child.status.state != ChildState::kRunning) continue;
    int wait_status = 0;
    const pid_t done = ::waitpid(child.status.pid, &wait_status, WNOHANG);
    if (done != child.status.pid) continue;
    // Drain what it wrote before it died.
    if (child.output_fd >= 0) {
      char buffer[65536];
      ssize_t n;
      while ((n = ::read(child.output_fd, buffer, sizeof buffer)) > 0) {
        child.partial.append(buffer, static_cast<std::size_t>(n));
      }
      std::size_t newline;
      while ((newline = child.partial.find('\n')) != std::string::npos) {
        emit(child, child.partial.substr(0, newline));
        child.partial.erase(0, newline + 1);
      }
      if (!child.partial.empty()) emit(child, child.partial);
      child.partial.clear();
      ::close(child.output_fd);
      child.output_fd = -1;
    }
    const bool signaled = WIFSIGNALED(wait_status);
    const int code = signaled ? 128 + WTERMSIG(wait_status) : WEXITSTATUS(wait_status);
    child.status.last_exit_code = code;
    child.status.pid = -1;
    const bool failed = code != 0;
    const double uptime_s = std::chrono::duration<double>(now - child.started_at).count();
    if (uptime_s >= child.spec.backoff.stable_s) child.consecutive_failures = 0;
    // A child we asked to stop (stop(), or the run's end for those that do not finish it) did
    // not fail, whatever its exit code.
    const bool stopped_by_us = stop_requested_ || (others_stopped_ && !child.spec.finishes_run);
    const bool may_restart = failed && child.spec.restart == RestartPolicy::kOnFailure &&
                             !stopped_by_us &&
                             (child.spec.backoff.max_restarts < 0 ||
                              child.status.restarts < child.spec.backoff.max_restarts);
    if (may_restart) {
      const auto& b = child.spec.backoff;
      const double delay_s =
          std::min(b.max_s, b.initial_s * std::pow(b.factor, child.consecutive_failures));
      ++child.consecutive_failures;
      child.restart_at =
          now + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(delay_s));
      child.status.state = ChildState::kWaitingRestart;
      INDRIVE_LOG(kWarn, "launch")
          << child.spec.name << " ended with " << (signaled ? "signal " : "code ")
          << (signaled ? code - 128 : code) << "; restarting in " << delay_s << " s";
    } else {
      child.status.state = failed && !stopped_by_us ? ChildState::kFailed : ChildState::kExited;
      INDRIVE_LOG_AT(failed ? log::Level::kWarn : log::Level::kInfo, "launch")
          << child.spec.name << " " << child_state_name(child.status.state) << " (code " << code
          << ")";
      if (child.spec.essential) essential_ended_ = true;
    }
  }
}

bool Supervisor::poll(std::chrono::milliseconds wait) {
  pump_output(wait);
  reap();
  const auto now = Clock::now();
  bool alive = false;
  for (Child* child : children_) {
    if (child->status.state == ChildState::kWaitingRestart && now >= child->restart_at &&
        !stop_requested_) {
      ++child->status.restarts;
      try {
        spawn(*child);
      } catch (const LaunchError& error) {
        INDRIVE_LOG(kError, "launch") << error.what();
        child->status.state = ChildState::kFailed;
      }
    }
    alive = alive || child->status.state == ChildState::kRunning ||
            child->status.state == ChildState::kWaitingRestart;
  }
  if (!essential_ended_) return alive && !stop_requested_;
  // The essential child is done: the children that finish the run go on to their own end.
  bool finishing = false;
  for (Child* child : children_) {
    if (!child->spec.finishes_run) continue;
    finishing = finishing || child->status.state == ChildState::kRunning ||
                child->status.state == ChildState::kWaitingRestart;
  }
  if (finishing && !others_stopped_) {
    others_stopped_ = true;
    for (Child* child : children_) {
      if (child->spec.finishes_run) continue;
      if (child->status.state == ChildState::kRunning) ::kill(-child->status.pid, SIGTERM);
      if (child->status.state == ChildState::kWaitingRestart) {
        child->status.state = ChildState::kExited;
      }
    }
  }
  return finishing && !stop_requested_;
}

void Supervisor::request_stop() { stop_requested_ = 1; }

bool Supervisor::signal_child(const std::string& name, int signal_number) {
  for (Child* child : children_) {
    if (child->spec.name == name && child->status.state == ChildState::kRunning) {
      return ::kill(-child->status.pid, signal_number) == 0;
    }
  }
  return false;
}

void Supervisor::stop(std::chrono::milliseconds grace) {
  stop_requested_ = 1;
  for (Child* child : children_) {
    if (child->status.state == ChildState::kRunning) ::kill(-child->status.pid, SIGTERM);
    if (child->status.state == ChildState::kWaitingRestart) {
      child->status.state = ChildState::kExited;
    }
  }
  const auto deadline = Clock::now() + grace;
  auto running = [&] {
    return std::any_of(children_.begin(), children_.end(),
                       [](Child* c) { return c->status.state == ChildState::kRunning; });
  };
  while (running() && Clock::now() < deadline) {
    pump_output(std::chrono::milliseconds(50));
    reap();
  }
  for (Child* child : children_) {
    if (child->status.state == ChildState::kRunning) {
      INDRIVE_LOG(kWarn, "launch") << child->spec.name << " did not stop within the grace "
                                   << "period; killing it";
      ::kill(-child->status.pid, SIGKILL);
    }
  }
  while (running()) {
    pump_output(std::chrono::milliseconds(20));
    reap();
  }
}

std::vector<ChildStatus> Supervisor::status() const {
  std::vector<ChildStatus> result;
  for (const Child* child : children_) result.push_back(child->status);
  return result;
}

}  // namespace indrive::deploy
