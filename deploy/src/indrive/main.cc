// `indrive`: the project's front door, one subcommand per file in deploy/src/indrive/.
//
//   indrive launch --config deploy/configs/smoke.yaml --run-id smoke --actors 2 --evaluators 1
#include <cstdio>
#include <memory>
#include <utility>
#include <vector>

#include "indrive/basics/log.h"
#include "indrive/command.h"

int main(int argc, char** argv) {
  using namespace indrive::cli;
  CLI::App app{"InDRiVE on SUMO: reward-free world-model pretraining for driving"};
  app.require_subcommand(1);
  std::string log_level = "info";
  app.add_option("--log-level", log_level, "debug, info, warn, error or off");
  std::vector<std::unique_ptr<Command>> commands;
  commands.push_back(launch_command());
  commands.push_back(report_command());
  commands.push_back(episodes_command());
  commands.push_back(plot_command());
  commands.push_back(compare_command());
  commands.push_back(dashboard_command());
  commands.push_back(snapshot_command());
  commands.push_back(untrained_command());
  std::vector<std::pair<CLI::App*, Command*>> added;
  for (const auto& command : commands) added.emplace_back(command->add_to(app), command.get());
  CLI11_PARSE(app, argc, argv);
  try {
    indrive::log::set_level(indrive::log::parse_level(log_level));
    for (const auto& [subcommand, command] : added) {
      if (*subcommand) return command->run();
    }
  } catch (const std::exception& error) {
    std::fprintf(stderr, "indrive: %s\n", error.what());
    return 1;
  }
  return 0;
}
