#include "indrive/actor/process_cli.h"

#include <signal.h>

namespace indrive::actor {
namespace {

std::atomic<bool> g_stop{false};

void on_stop_signal(int) { g_stop.store(true); }

}  // namespace

void add_service_options(CLI::App& app, ServiceOptions& options, std::string& log_level) {
  app.add_option("--config", options.config_file, "run configuration (YAML)")
      ->check(CLI::ExistingFile);
  app.add_option("--run-dir", options.run_dir, "run directory; its name is the run id")->required();
  app.add_option("--domain", options.domain_id, "DDS domain id")->check(CLI::Range(0, 232));
  app.add_option("--dds-profile", options.dds_profile, "Fast DDS XML profiles file")
      ->check(CLI::ExistingFile);
  app.add_option("--set", options.overrides, "config override key=value (repeatable)");
  app.add_option("--log-level", log_level, "debug, info, warn, error or off")
      ->capture_default_str();
}

const std::atomic<bool>& install_stop_signals() {
  struct sigaction action {};
  action.sa_handler = on_stop_signal;
  sigemptyset(&action.sa_mask);
  sigaction(SIGINT, &action, nullptr);
  sigaction(SIGTERM, &action, nullptr);
  return g_stop;
}

}  // namespace indrive::actor
