#include "indrive/service/process_cli.h"

#include <pthread.h>
#include <signal.h>
#include <string.h>

#include <filesystem>
#include <thread>

#include "indrive/basics/log.h"
#include "indrive/dds/participant.h"
#include "indrive/dds/security.h"

namespace indrive::service {
namespace {

std::atomic<bool> g_stop{false};

// ", discovery server HOST:PORT ..." when one is set by flag, key or environment, resolved
// here so that --check-config shows a name that does not resolve.
std::string discovery_summary(const ServiceConfig& config) {
  const auto server =
      dds::resolve_discovery_server(config.participant_options("").discovery_server);
  return server ? ", discovery server " + server->describe() : "";
}

// ", DDS Security as ROLE from DIR" once the role's files pass check_security_files, which
// throws naming the bad file; "" without security.
std::string security_summary(const ServiceConfig& config, const std::string& own_role) {
  const dds::ParticipantOptions options = config.participant_options(own_role);
  if (options.security_dir.empty() || own_role.empty()) return "";
  dds::check_security_files(options.security_dir, options.security_role);
  return ", DDS Security as " + options.security_role + " from " + options.security_dir +
         " (certificate, key, permissions and governance checked)";
}

// Threads of this process now.
std::size_t thread_count() {
  std::error_code error;
  std::size_t count = 0;
  for (auto it = std::filesystem::directory_iterator("/proc/self/task", error);
       !error && it != std::filesystem::directory_iterator(); it.increment(error)) {
    ++count;
  }
  return count;
}

}  // namespace

void add_service_options(CLI::App& app, ServiceOptions& options, std::string& log_level) {
  app.add_option("--config", options.config_file, "run configuration (YAML)")
      ->check(CLI::ExistingFile);
  app.add_option("--run-dir", options.run_dir, "run directory; its name is the run id")->required();
  app.add_option("--domain", options.domain_id, "DDS domain id")->check(CLI::Range(0, 232));
  app.add_option("--dds-profile", options.dds_profile, "Fast DDS XML profiles file")
      ->check(CLI::ExistingFile);
  app.add_option("--discovery-server", options.discovery_server,
                 "HOST:PORT of the DDS discovery server (with the discovery_server.xml profile); "
                 "default: $INDRIVE_DISCOVERY_SERVER, then the profile's address");
  app.add_option("--dds-security", options.dds_security,
                 "DDS Security folder made by deploy/dds/make_security.sh (default: none)")
      ->check(CLI::ExistingDirectory);
  app.add_option("--set", options.overrides, "config override key=value (repeatable)");
  app.add_option("--log-level", log_level, "debug, info, warn, error or off")
      ->capture_default_str();
  app.add_flag("--check-config", options.check_only,
               "resolve the configuration and DDS profile, print a summary and exit");
}

std::string check_summary(const ServiceConfig& config, const std::string& own_role) {
  const agent::AgentConfig agent = config.agent();
  return "config ok: run '" + config.run_id() + "', preset " + agent.preset + ", phase " +
         std::string(agent::to_string(agent.phase)) + ", domain " +
         std::to_string(config.domain_id()) + ", DDS profiles " +
         dds::resolve_profiles_file(config.dds_profile()).string() + discovery_summary(config) +
         security_summary(config, own_role);
}

const std::atomic<bool>& install_stop_signals() {
  // A handler would run on whichever thread the kernel picks, on that thread's stack pointer,
  // and oneDNN 2.6's jit sgemm points the stack pointer at a heap workspace while it runs (K
  // blocks over 252 on AVX2 and AVX-512; fixed upstream in oneDNN 3.11): the signal frame then
  // lands on the heap below the workspace and corrupts it, and the process aborts later in
  // malloc. So the signals are blocked here, before the program starts any thread, which
  // every later thread inherits, and are taken by sigwait on a thread of their own (named
  // stop-signals; while it waits, the kernel shows them unblocked in its mask).
  static const bool installed = [] {
    if (const std::size_t threads = thread_count();
        threads > 1 && !stop_signals_blocked_before_libraries()) {
      INDRIVE_LOG(kWarn, "process")
          << threads - 1 << " thread(s) started before the stop signals were installed may "
          << "still take SIGINT or SIGTERM (call install_stop_signals() first in main, and link "
             "the program with indrive::stop_signals_preinit)";
    }
    sigset_t stops;
    sigemptyset(&stops);
    sigaddset(&stops, SIGINT);
    sigaddset(&stops, SIGTERM);
    pthread_sigmask(SIG_BLOCK, &stops, nullptr);
    std::thread([stops] {
      pthread_setname_np(pthread_self(), "stop-signals");
      for (;;) {
        int signal = 0;
        if (sigwait(&stops, &signal) != 0) continue;
        if (!g_stop.exchange(true)) {
          INDRIVE_LOG(kInfo, "process") << "SIG" << sigabbrev_np(signal) << " received: stopping";
        }
      }
    }).detach();
    return true;
  }();
  (void)installed;
  return g_stop;
}

// The programs link the definition that says whether it worked (stop_signals_preinit.cc).
[[gnu::weak]] bool stop_signals_blocked_before_libraries() { return false; }

}  // namespace indrive::service
