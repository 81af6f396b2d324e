// `indrive compare`: one metric of several runs in one PNG.
#include <cstdio>
#include <stdexcept>

#include "command.h"

namespace indrive::cli {
namespace {

namespace fs = std::filesystem;

class CompareCommand final : public Command {
 public:
  CLI::App* add_to(CLI::App& app) override {
    auto* command = app.add_subcommand(
        "compare",
        "draw one metric of several runs (metrics.jsonl) into one PNG, a line per run or per "
        "group of runs");
    runs_.add_to(command,
                 "runs drawn as one line, their mean, with a band from the lowest to the highest "
                 "(e.g. the seeds of one method)");
    command->add_option("--metric", metric_, "metrics.jsonl key, e.g. wm/recon")->required();
    command->add_option("--out", out_, "PNG to write")->capture_default_str();
    command->add_option("--x", x_, "metric on the x axis")->capture_default_str();
    command
        ->add_option("--smooth", smoothing_,
                     "running-average weight for noisy metrics such as losses (0: none, 0.9: "
                     "strong)")
        ->check(CLI::Range(0.0, 0.999))
        ->capture_default_str();
    return command;
  }

  int run() override {
    if (runs_.empty()) {
      throw std::invalid_argument("compare: name run directories or --group LABEL=RUN,RUN");
    }
    const auto ends = deploy::plot_compare(runs_.parse(), metric_, out_, x_, smoothing_);
    std::printf("%s\n", out_.c_str());
    // The figures behind the picture, where each line ends.
    for (const auto& end : ends) {
      std::printf("  %-40s %s %.6g: %.6g", end.label.c_str(), x_.c_str(), end.x, end.y);
      if (end.low != end.high) std::printf(" (%.6g to %.6g)", end.low, end.high);
      std::printf("\n");
    }
    return 0;
  }

 private:
  RunOptions runs_;
  std::string metric_;
  fs::path out_ = "compare.png";
  std::string x_ = "env_steps";
  double smoothing_ = 0.0;
};

}  // namespace

std::unique_ptr<Command> compare_command() { return std::make_unique<CompareCommand>(); }

}  // namespace indrive::cli
