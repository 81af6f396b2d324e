// `indrive`: the project's front door.
//
//   indrive launch --config deploy/configs/smoke.yaml --run-id smoke --actors 2 --evaluators 1
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <cstdio>
#include <filesystem>
#include <string>

#include "indrive/common/log.h"
#include "indrive/deploy/launch.h"

namespace fs = std::filesystem;

namespace {

// The folder of this executable: its sibling programs live there (build/bin).
fs::path own_folder() {
  std::error_code error;
  const fs::path self = fs::read_symlink("/proc/self/exe", error);
  return error ? fs::current_path() : self.parent_path();
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"InDRiVE on SUMO: reward-free world-model pretraining for driving"};
  app.require_subcommand(1);
  std::string log_level = "info";
  app.add_option("--log-level", log_level, "debug, info, warn, error or off");

  indrive::deploy::LaunchOptions launch;
  auto* launch_cmd = app.add_subcommand(
      "launch", "start the learner, actors and evaluators of one run on this host");
  launch_cmd->add_option("--config", launch.config, "run configuration (YAML)")
      ->required()
      ->check(CLI::ExistingFile);
  launch_cmd->add_option("--run-id", launch.run_id, "name of the run (folder under --runs-dir)")
      ->required();
  launch_cmd->add_option("--runs-dir", launch.runs_dir, "where run folders live")
      ->capture_default_str();
  launch_cmd->add_option("--actors", launch.actors, "actor processes")
      ->check(CLI::Range(0, 64))
      ->capture_default_str();
  launch_cmd->add_option("--evaluators", launch.evaluators, "evaluator processes")
      ->check(CLI::Range(0, 64))
      ->capture_default_str();
  launch_cmd->add_option("--domain", launch.domain_id, "DDS domain id")
      ->check(CLI::Range(0, 232))
      ->capture_default_str();
  launch_cmd->add_option("--dds-profile", launch.dds_profile, "Fast DDS XML profiles file")
      ->check(CLI::ExistingFile);
  launch_cmd->add_option("--set", launch.overrides, "config override key=value (repeatable)");
  launch_cmd
      ->add_option("--status-interval", launch.status_interval_s,
                   "seconds between combined status lines")
      ->capture_default_str();

  CLI11_PARSE(app, argc, argv);
  try {
    indrive::log::set_level(indrive::log::parse_level(log_level));
    if (*launch_cmd) {
      launch.bin_dir = own_folder();
      return indrive::deploy::run_launch(launch);
    }
  } catch (const std::exception& error) {
    std::fprintf(stderr, "indrive: %s\n", error.what());
    return 1;
  }
  return 0;
}
