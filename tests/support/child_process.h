// Child processes for tests and benchmarks that start the project's programs: output appended to
// a log file, killed and reaped when the object dies.
//
//   testing::Child learner({bin / "indrive-learner", "--config", cfg}, dir / "learner.log");
//   learner.signal(SIGTERM);
//   EXPECT_EQ(learner.wait(30s), 0) << testing::slurp(dir / "learner.log");
#pragma once

#include <sys/types.h>

#include <chrono>
#include <filesystem>
#include <map>
#include <string>
#include <vector>

namespace indrive::testing {

class Child {
 public:
  // Starts argv[0] (a path) with stdout and stderr appended to `log`, in this process's
  // environment with `env` set on top; throws std::runtime_error if it cannot start. The child
  // is killed when the test process dies (PR_SET_PDEATHSIG); create it in the thread that lives
  // as long as it should (the signal goes when the creating thread ends).
  Child(std::vector<std::string> argv, const std::filesystem::path& log,
        const std::map<std::string, std::string>& env = {});
  ~Child();  // SIGKILLs and reaps a process still running
  Child(const Child&) = delete;
  Child& operator=(const Child&) = delete;

  // Sends a signal to the process.
  void signal(int number);
  // Waits for the exit and returns its exit code, 128 + signal for a signal, -1 on timeout.
  int wait(std::chrono::milliseconds timeout);
  // Sends SIGTERM and waits up to `grace`, then SIGKILLs; returns the exit status as wait().
  int stop(std::chrono::milliseconds grace);
  // True while the process has not exited.
  bool running();
  pid_t pid() const { return pid_; }

 private:
  pid_t pid_ = -1;
};

// The whole text of a file ("" when it is missing).
std::string slurp(const std::filesystem::path& path);
// Writes `text` as the whole file, making its folders first.
void write_text(const std::filesystem::path& path, const std::string& text);

}  // namespace indrive::testing
