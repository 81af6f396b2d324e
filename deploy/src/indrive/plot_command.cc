// `indrive plot`: a run's learning curves and coverage map into <run>/plots/.
#include <cstdio>
#include <stdexcept>

#include "command.h"

namespace indrive::cli {
namespace {

namespace fs = std::filesystem;

class PlotCommand final : public Command {
 public:
  CLI::App* add_to(CLI::App& app) override {
    auto* command = app.add_subcommand(
        "plot",
        "draw learning curves (metrics.jsonl, eval/curve-*.csv) and the coverage map of a run "
        "into <run>/plots/");
    command->add_option("run", run_, "run directory")->required()->check(CLI::ExistingDirectory);
    command->add_option("--x", x_, "metric on the x axis")->capture_default_str();
    return command;
  }

  int run() override {
    const bool has_metrics = fs::exists(run_ / "metrics.jsonl");
    if (has_metrics) {
      for (const auto& file : deploy::plot_metrics(run_ / "metrics.jsonl", run_ / "plots", x_)) {
        std::printf("%s\n", file.c_str());
      }
    }
    const auto map = deploy::plot_coverage(run_, run_ / "plots" / "coverage_map.png");
    if (map) std::printf("%s\n", map->c_str());
    const auto curves = deploy::plot_eval_curves(run_, run_ / "plots");
    for (const auto& file : curves) std::printf("%s\n", file.c_str());
    if (!has_metrics && !map && curves.empty()) {
      throw std::runtime_error(run_.string() +
                               " has no metrics.jsonl, coverage files or eval learning curves: "
                               "is it a run directory?");
    }
    return 0;
  }

 private:
  fs::path run_;
  std::string x_ = "env_steps";
};

}  // namespace

std::unique_ptr<Command> plot_command() { return std::make_unique<PlotCommand>(); }

}  // namespace indrive::cli
