// The command line both service executables share (fixed by `indrive launch`):
//   --config FILE --run-dir DIR --domain N [--dds-profile XML] [--set key=value]...
//   [--check-config]
// plus a stop flag that SIGINT and SIGTERM set.
#pragma once

#include <CLI/CLI.hpp>
#include <atomic>
#include <string>

#include "indrive/service/run_config.h"

namespace indrive::service {

// Adds the shared options to `app`, writing into `options` and `log_level`.
void add_service_options(CLI::App& app, ServiceOptions& options, std::string& log_level);

// One line that says what a process would run with (run id, preset, phase, domain, DDS
// profile, discovery server, security role and folder); throws dds::DdsError when the profiles
// file cannot be found or, with --dds-security, when a security file of `own_role` (the
// program's role unless dds.security_role says otherwise) is missing, expired or wrongly
// signed. Printed by --check-config, which validates a command line without starting anything.
std::string check_summary(const ServiceConfig& config, const std::string& own_role);

// The flag SIGINT and SIGTERM set (installed once per process; call it first in main, before
// any thread starts). The signals are blocked in the calling thread, and so in every thread it
// starts later, and taken by sigwait on a thread of their own, never by a handler on a
// computing thread: oneDNN 2.6's jit sgemm moves the stack pointer into a heap workspace, where
// a signal frame corrupts the heap (process_cli.cc). Children spawned by these programs get
// their signals back with ChildSignals (indrive/basics/child_signals.h).
const std::atomic<bool>& install_stop_signals();

// Whether the program blocked SIGINT and SIGTERM before its shared libraries' constructors ran
// (src/stop_signals_preinit.cc, linked into the programs through indrive::stop_signals_preinit;
// false in anything else).
bool stop_signals_blocked_before_libraries();

}  // namespace indrive::service
