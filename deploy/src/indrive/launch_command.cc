// `indrive launch`: the learner, actors and evaluators of one run on this host.
#include "command.h"
#include "indrive/basics/data_path.h"
#include "indrive/deploy/launch.h"

namespace indrive::cli {
namespace {

class LaunchCommand final : public Command {
 public:
  CLI::App* add_to(CLI::App& app) override {
    auto* command = app.add_subcommand(
        "launch", "start the learner, actors and evaluators of one run on this host");
    command->add_option("--config", options_.config, "run configuration (YAML)")
        ->required()
        ->check(CLI::ExistingFile);
    command->add_option("--run-id", options_.run_id, "name of the run (folder under --runs-dir)")
        ->required();
    command->add_option("--runs-dir", options_.runs_dir, "where run folders live")
        ->capture_default_str();
    command->add_option("--actors", options_.actors, "actor processes")
        ->check(CLI::Range(0, 64))
        ->capture_default_str();
    command->add_option("--evaluators", options_.evaluators, "evaluator processes")
        ->check(CLI::Range(0, 64))
        ->capture_default_str();
    command->add_option("--domain", options_.domain_id, "DDS domain id")
        ->check(CLI::Range(0, 232))
        ->capture_default_str();
    command->add_option("--dds-profile", options_.dds_profile, "Fast DDS XML profiles file")
        ->check(CLI::ExistingFile);
    command
        ->add_option("--dds-security", options_.dds_security,
                     "DDS Security folder made by deploy/dds/make_security.sh (default: none)")
        ->check(CLI::ExistingDirectory);
    command->add_option("--set", options_.overrides, "config override key=value (repeatable)");
    command
        ->add_option("--status-interval", options_.status_interval_s,
                     "seconds between combined status lines")
        ->capture_default_str();
    command
        ->add_option("--dashboard-interval", options_.dashboard_interval_s,
                     "seconds between rewrites of the run's page, <run>/index.html (0: none)")
        ->check(CLI::Range(0.0, 86400.0))
        ->capture_default_str();
    return command;
  }

  int run() override {
    options_.bin_dir = own_program_folder();
    // Before the children start: OpenMP reads these once, when a process loads it.
    deploy::set_openmp_wait_defaults();
    return deploy::run_launch(options_);
  }

 private:
  deploy::LaunchOptions options_;
};

}  // namespace

std::unique_ptr<Command> launch_command() { return std::make_unique<LaunchCommand>(); }

}  // namespace indrive::cli
