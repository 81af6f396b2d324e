#include "indrive/basics/child_signals.h"

#include <signal.h>

namespace indrive {
namespace {

constexpr int kDefaulted[] = {SIGINT, SIGTERM, SIGPIPE, SIGCHLD};

}  // namespace

ChildSignals::ChildSignals() {
  posix_spawnattr_init(&attributes_);
  sigset_t none;
  sigemptyset(&none);
  posix_spawnattr_setsigmask(&attributes_, &none);
  sigset_t defaulted;
  sigemptyset(&defaulted);
  for (int signal : kDefaulted) sigaddset(&defaulted, signal);
  posix_spawnattr_setsigdefault(&attributes_, &defaulted);
  posix_spawnattr_setflags(&attributes_, POSIX_SPAWN_SETSIGMASK | POSIX_SPAWN_SETSIGDEF);
}

ChildSignals::~ChildSignals() { posix_spawnattr_destroy(&attributes_); }

void reset_signals_for_exec() {
  for (int signal : kDefaulted) ::signal(signal, SIG_DFL);
  sigset_t none;
  sigemptyset(&none);
  sigprocmask(SIG_SETMASK, &none, nullptr);
}

}  // namespace indrive
