// The signal state a child process starts with.
//
// The programs that compute (learner, actor, evaluator, local trainer) take SIGINT and SIGTERM
// on a thread of their own and block them in every other thread
// (service::install_stop_signals, docs/operations.md). A blocked signal mask
// survives exec: a child started as it is would keep SIGTERM pending forever and could only be
// killed. Children are therefore started with nothing blocked and every signal at its default
// action:
//
//   ChildSignals child_signals;
//   posix_spawn(&pid, path, &actions, child_signals.attributes(), argv, environ);
//
//   if (fork() == 0) { reset_signals_for_exec(); execvp(...); }
#pragma once

#include <spawn.h>

namespace indrive {

// posix_spawn attributes: an empty signal mask, and SIGINT, SIGTERM, SIGPIPE and SIGCHLD at
// their default actions (a parent may ignore SIGPIPE, which exec would keep).
class ChildSignals {
 public:
  ChildSignals();
  ~ChildSignals();
  ChildSignals(const ChildSignals&) = delete;
  ChildSignals& operator=(const ChildSignals&) = delete;

  const posix_spawnattr_t* attributes() const { return &attributes_; }

 private:
  posix_spawnattr_t attributes_;
};

// The same for a forked child, before it calls exec (async-signal-safe).
void reset_signals_for_exec();

}  // namespace indrive
