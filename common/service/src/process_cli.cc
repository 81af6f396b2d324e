#include "indrive/service/process_cli.h"

#include <signal.h>

#include "indrive/dds/participant.h"
#include "indrive/dds/security.h"

namespace indrive::service {
namespace {

std::atomic<bool> g_stop{false};

void on_stop_signal(int) { g_stop.store(true); }

// ", discovery server HOST:PORT ..." when one is set by flag, key or environment, resolved
// here so that --check-config shows a name that does not resolve.
std::string discovery_summary(const ServiceConfig& config) {
  const auto server =
      dds::resolve_discovery_server(config.config().get<std::string>("dds.discovery_server"));
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
  struct sigaction action {};
  action.sa_handler = on_stop_signal;
  sigemptyset(&action.sa_mask);
  sigaction(SIGINT, &action, nullptr);
  sigaction(SIGTERM, &action, nullptr);
  return g_stop;
}

}  // namespace indrive::service
