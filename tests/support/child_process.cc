#include "child_process.h"

#include <fcntl.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <fstream>
#include <iterator>
#include <stdexcept>
#include <thread>

extern char** environ;

namespace indrive::testing {

Child::Child(std::vector<std::string> argv, const std::filesystem::path& log,
             const std::map<std::string, std::string>& env) {
  std::vector<std::string> env_text;
  for (const auto& [key, value] : env) env_text.push_back(key + "=" + value);
  for (char** entry = environ; *entry != nullptr; ++entry) {
    const std::string text(*entry);
    if (!env.contains(text.substr(0, text.find('=')))) env_text.push_back(text);
  }
  std::vector<char*> env_ptrs;
  for (auto& entry : env_text) env_ptrs.push_back(entry.data());
  env_ptrs.push_back(nullptr);
  std::vector<char*> args;
  for (auto& arg : argv) args.push_back(arg.data());
  args.push_back(nullptr);

  // fork and exec instead of posix_spawn, to set PR_SET_PDEATHSIG: a test process that dies
  // without running its destructors (ctest's timeout kills it) takes its children along instead
  // of leaving a learner and actors training for the rest of the suite. Only async-signal-safe
  // calls after the fork; an exec failure comes back through a close-on-exec pipe.
  int exec_fds[2];
  if (::pipe2(exec_fds, O_CLOEXEC) != 0) throw std::runtime_error("cannot start " + argv[0]);
  const pid_t parent = ::getpid();
  const std::string log_path = log.string();
  pid_ = ::fork();
  if (pid_ < 0) {
    ::close(exec_fds[0]);
    ::close(exec_fds[1]);
    throw std::runtime_error("cannot start " + argv[0] + ": fork failed");
  }
  if (pid_ == 0) {
    ::prctl(PR_SET_PDEATHSIG, SIGKILL);
    if (::getppid() != parent) ::_exit(127);  // the test died before prctl
    const int fd = ::open(log_path.c_str(), O_WRONLY | O_CREAT | O_APPEND, 0644);
    if (fd >= 0) {
      ::dup2(fd, STDOUT_FILENO);
      ::dup2(fd, STDERR_FILENO);
      if (fd > STDERR_FILENO) ::close(fd);
    }
    ::execve(args[0], args.data(), env_ptrs.data());
    const int error = errno;
    [[maybe_unused]] const auto written = ::write(exec_fds[1], &error, sizeof error);
    ::_exit(127);
  }
  ::close(exec_fds[1]);
  int exec_error = 0;
  const auto got = ::read(exec_fds[0], &exec_error, sizeof exec_error);
  ::close(exec_fds[0]);
  if (got == static_cast<ssize_t>(sizeof exec_error)) {
    ::waitpid(pid_, nullptr, 0);
    pid_ = -1;
    throw std::runtime_error("cannot start " + argv[0] + ": " + std::strerror(exec_error));
  }
}

Child::~Child() {
  if (pid_ > 0) {
    ::kill(pid_, SIGKILL);
    ::waitpid(pid_, nullptr, 0);
  }
}

void Child::signal(int number) {
  if (pid_ > 0) ::kill(pid_, number);
}

int Child::wait(std::chrono::milliseconds timeout) {
  const auto end = std::chrono::steady_clock::now() + timeout;
  while (pid_ > 0) {
    int status = 0;
    if (::waitpid(pid_, &status, WNOHANG) == pid_) {
      pid_ = -1;
      return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
    }
    if (std::chrono::steady_clock::now() >= end) return -1;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  return -1;
}

int Child::stop(std::chrono::milliseconds grace) {
  signal(SIGTERM);
  const int code = wait(grace);
  if (code >= 0 || pid_ <= 0) return code;
  ::kill(pid_, SIGKILL);
  int status = 0;
  ::waitpid(pid_, &status, 0);
  pid_ = -1;
  return 128 + SIGKILL;
}

bool Child::running() {
  int status = 0;
  if (pid_ <= 0) return false;
  if (::waitpid(pid_, &status, WNOHANG) != pid_) return true;
  pid_ = -1;
  return false;
}

std::string slurp(const std::filesystem::path& path) {
  std::ifstream in(path);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

void write_text(const std::filesystem::path& path, const std::string& text) {
  std::filesystem::create_directories(path.parent_path());
  std::ofstream(path) << text;
}

}  // namespace indrive::testing
