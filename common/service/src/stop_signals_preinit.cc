// Linked into each program that takes its stop signals with install_stop_signals (learner,
// actor, local trainer; CMake target indrive::stop_signals_preinit). A shared library may start
// threads in its constructor, before main runs (OpenBLAS's pthread build, which OpenCV and SUMO
// load where it is the system BLAS, starts its pool so): such a thread blocks nothing, and a
// SIGTERM given to it would end the process at once, or run a handler on it. The program's
// .preinit_array runs before any shared library's constructor, while the process has one
// thread: blocking SIGINT and SIGTERM there makes every thread inherit the block.
// install_stop_signals then takes them on a thread of its own; one sent before that waits,
// pending, and stops the program as soon as it is installed.
#include <signal.h>

#include "indrive/service/process_cli.h"

namespace indrive::service {
namespace {

bool g_blocked_before_libraries = false;

void block_stop_signals(int, char**, char**) {
  sigset_t stops;
  sigemptyset(&stops);
  sigaddset(&stops, SIGINT);
  sigaddset(&stops, SIGTERM);
  g_blocked_before_libraries = sigprocmask(SIG_BLOCK, &stops, nullptr) == 0;
}

[[gnu::section(".preinit_array"),
  gnu::used]] void (*const kBlockStopSignals)(int, char**, char**) = block_stop_signals;

}  // namespace

bool stop_signals_blocked_before_libraries() { return g_blocked_before_libraries; }

}  // namespace indrive::service
