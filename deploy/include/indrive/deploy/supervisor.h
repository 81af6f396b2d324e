// Process supervision for `indrive launch`: starts the learner, actors and evaluators of one
// host as child processes, restarts crashed ones with exponential back-off, collects their
// output line by line, and stops them all cleanly.
//
//   Supervisor supervisor;
//   supervisor.add({.name = "learner", .argv = {"indrive-learner", "--run", dir}});
//   supervisor.add({.name = "actor-0", .argv = {...}, .restart = RestartPolicy::kOnFailure});
//   supervisor.on_line([](const std::string& name, const std::string& line) { ... });
//   supervisor.start();
//   while (supervisor.poll(std::chrono::milliseconds(200))) { /* draw progress */ }
//   supervisor.stop(std::chrono::seconds(10));
#pragma once

#include <sys/types.h>

#include <chrono>
#include <filesystem>
#include <functional>
#include <map>
#include <stdexcept>
#include <string>
#include <vector>

namespace indrive::deploy {

// Raised when a child cannot be started at all (missing executable, fork failure).
class LaunchError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

enum class RestartPolicy {
  kNever,      // an exit of any kind is final (evaluators that finish their grid)
  kOnFailure,  // restart after a non-zero exit or a signal (actors)
};

// Waits between restarts: initial_s, then times factor, capped at max_s; a child that stayed
// up for stable_s counts as healthy again and its next restart waits initial_s.
struct Backoff {
  double initial_s = 1.0;
  double factor = 2.0;
  double max_s = 30.0;
  double stable_s = 60.0;
  int max_restarts = -1;  // -1: no limit
};

struct ProcessSpec {
  std::string name;                        // shown as the prefix of its output lines
  std::vector<std::string> argv;           // argv[0] is the executable (path or PATH name)
  std::map<std::string, std::string> env;  // added to the launcher's environment
  RestartPolicy restart = RestartPolicy::kNever;
  Backoff backoff;
  bool essential = false;  // when an essential child ends for good, the supervisor stops all
  // ... except children that finish the run: they keep running to their own end (evaluators
  // evaluating the run's final snapshot); the others get SIGTERM at once.
  bool finishes_run = false;
  std::filesystem::path log_file;  // optional: every output line is appended here too
};

enum class ChildState { kPending, kRunning, kWaitingRestart, kExited, kFailed };
const char* child_state_name(ChildState state);

// What the supervisor knows of one child.
struct ChildStatus {
  std::string name;
  ChildState state = ChildState::kPending;
  pid_t pid = -1;
  int restarts = 0;
  int last_exit_code = 0;  // exit status, or 128 + signal number
  std::string last_line;   // newest output line, for progress views
};

class Supervisor {
 public:
  Supervisor();
  ~Supervisor();  // stops every child still running (grace 5 s)
  Supervisor(const Supervisor&) = delete;
  Supervisor& operator=(const Supervisor&) = delete;

  // Registers a child; call before start().
  void add(ProcessSpec spec);
  // Receives every output line (stdout and stderr) of every child, in arrival order.
  void on_line(std::function<void(const std::string& name, const std::string& line)> callback);
  // Starts every registered child. Throws LaunchError if one cannot be started.
  void start();
  // Pumps output, reaps exits and performs due restarts for up to `wait`. Returns false once
  // there is nothing left to supervise: every child ended for good, an essential child ended
  // and no child that finishes the run is left, or stop() was requested.
  bool poll(std::chrono::milliseconds wait);
  // Sends SIGTERM to every running child, waits up to `grace`, then SIGKILLs the rest.
  void stop(std::chrono::milliseconds grace);
  // Asks poll() to return false at its next call (safe from a signal handler).
  void request_stop();
  // Sends a signal to one running child (for tests and for forwarding).
  bool signal_child(const std::string& name, int signal_number);

  std::vector<ChildStatus> status() const;

 private:
  struct Child;
  void spawn(Child& child);
  void pump_output(std::chrono::milliseconds wait);
  void reap();
  void emit(Child& child, const std::string& line);

  std::vector<Child*> children_;
  std::function<void(const std::string&, const std::string&)> on_line_;
  volatile int stop_requested_ = 0;
  bool essential_ended_ = false;
  bool others_stopped_ = false;  // SIGTERM sent to the children that do not finish the run
};

}  // namespace indrive::deploy
