// `indrive episodes`: how training went per route, from runs' train-episodes.csv.
#include <cstdio>

#include "command.h"
#include "indrive/deploy/training_episodes.h"

namespace indrive::cli {
namespace {

namespace fs = std::filesystem;

class EpisodesCommand final : public Command {
 public:
  CLI::App* add_to(CLI::App& app) override {
    auto* command = app.add_subcommand(
        "episodes",
        "how training went per route, from runs' train-episodes.csv: episodes, SR, route "
        "completion and return per route, over all episodes and the newest --last, and the "
        "return balanced over routes");
    command->add_option("runs", inputs_, "run directories or train-episodes.csv files")->required();
    command->add_option("--last", last_, "newest episodes per route behind last-N")
        ->check(CLI::PositiveNumber)
        ->capture_default_str();
    return command;
  }

  int run() override {
    std::vector<deploy::RunTraining> runs;
    for (const fs::path& input : inputs_) {
      runs.push_back(deploy::summarize_training(deploy::load_training_episodes(input), last_));
      runs.back().label = input.string();
    }
    std::fputs(deploy::render_training(runs, last_).c_str(), stdout);
    return 0;
  }

 private:
  std::vector<fs::path> inputs_;
  int last_ = 5;
};

}  // namespace

std::unique_ptr<Command> episodes_command() { return std::make_unique<EpisodesCommand>(); }

}  // namespace indrive::cli
