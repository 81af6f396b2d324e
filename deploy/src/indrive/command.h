// The `indrive` subcommands, one file each: a Command registers its options on the program's
// CLI11 app (the options write into the command object) and runs once the line is parsed.
//
//   CLI::App app;
//   auto report = report_command();
//   CLI::App* sub = report->add_to(app);
//   CLI11_PARSE(app, argc, argv);
//   if (*sub) return report->run();
#pragma once

#include <CLI/CLI.hpp>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "indrive/deploy/plot.h"

namespace indrive::cli {

class Command {
 public:
  virtual ~Command() = default;
  // Adds the subcommand with its options to `app`; returns it (true after parsing when given).
  virtual CLI::App* add_to(CLI::App& app) = 0;
  // Does the work; returns the exit status. Throws on bad input (main prints the message).
  virtual int run() = 0;
};

std::unique_ptr<Command> launch_command();
std::unique_ptr<Command> report_command();
std::unique_ptr<Command> episodes_command();
std::unique_ptr<Command> plot_command();
std::unique_ptr<Command> compare_command();
std::unique_ptr<Command> dashboard_command();
std::unique_ptr<Command> snapshot_command();
std::unique_ptr<Command> untrained_command();

// For the subcommands that draw several runs (compare, dashboard): positional run directories,
// each its own line, and repeatable --group LABEL=RUN[,RUN...] drawn as their mean with a min-max
// band.
struct RunOptions {
  std::vector<std::filesystem::path> runs;
  std::vector<std::string> groups;
  void add_to(CLI::App* command, const std::string& group_help);
  // One group per positional run, then one per --group, whose runs must be directories.
  std::vector<deploy::CompareGroup> parse() const;
  bool empty() const { return runs.empty() && groups.empty(); }
};

}  // namespace indrive::cli
