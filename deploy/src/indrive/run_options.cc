#include <stdexcept>

#include "command.h"

namespace indrive::cli {

namespace fs = std::filesystem;

void RunOptions::add_to(CLI::App* command, const std::string& group_help) {
  command->add_option("runs", runs, "run directories, each its own line")
      ->check(CLI::ExistingDirectory);
  command->add_option("--group", groups, "LABEL=RUN[,RUN...]: " + group_help + "; repeatable")
      ->expected(1)
      ->allow_extra_args(false)
      ->multi_option_policy(CLI::MultiOptionPolicy::TakeAll);
}

std::vector<deploy::CompareGroup> RunOptions::parse() const {
  std::vector<deploy::CompareGroup> parsed;
  for (const auto& run : runs) parsed.push_back(deploy::single_run_group(run));
  for (const auto& spec : groups) {
    parsed.push_back(deploy::parse_compare_group(spec));
    for (const auto& run : parsed.back().runs) {
      if (!fs::is_directory(run)) {
        throw std::invalid_argument("--group " + spec + ": " + run.string() +
                                    " is not a directory");
      }
    }
  }
  return parsed;
}

}  // namespace indrive::cli
