// `indrive report`: the paper's tables from evaluation results.
#include <cstdio>

#include "command.h"
#include "indrive/basics/run_dir.h"
#include "indrive/deploy/report.h"
#include "indrive/envserver/town.h"

namespace indrive::cli {
namespace {

namespace fs = std::filesystem;

class ReportCommand final : public Command {
 public:
  CLI::App* add_to(CLI::App& app) override {
    auto* command = app.add_subcommand(
        "report", "write the paper's tables (report.md, report.csv, report.tex) from results");
    command->add_option("inputs", inputs_, "run directories, eval folders or CSV files")
        ->required();
    command->add_option("--out", out_, "output folder")->capture_default_str();
    command->add_option("--seen-town", seen_town_, "training town for the gap")
        ->capture_default_str();
    command->add_option("--heldout-town", heldout_town_, "held-out town for the gap")
        ->capture_default_str();
    command
        ->add_option("--route-set", route_set_,
                     "env.route_set the evaluations ran with: the layout bound row is computed "
                     "on the built-in towns' routes of this set")
        ->check(
            CLI::IsMember(std::vector<std::string>(env::kRouteSets.begin(), env::kRouteSets.end())))
        ->capture_default_str();
    return command;
  }

  int run() override {
    const auto records = deploy::load_results(inputs_);
    const auto report = deploy::aggregate(records);
    fs::create_directories(out_);
    atomic_write(out_ / "report.md",
                 deploy::render_markdown(report, seen_town_, heldout_town_,
                                         deploy::route_choices_of(report, route_set_), route_set_));
    atomic_write(out_ / "report.csv", deploy::render_csv(report));
    atomic_write(out_ / "report.tex", deploy::render_latex(report));
    std::printf("%d episodes from %zu run(s) -> %s/report.md (.csv, .tex)\n", report.episodes,
                report.runs.size(), out_.c_str());
    return 0;
  }

 private:
  std::vector<fs::path> inputs_;
  fs::path out_ = "report";
  std::string seen_town_ = "town01";
  std::string heldout_town_ = "town02";
  std::string route_set_ = "right";
};

}  // namespace

std::unique_ptr<Command> report_command() { return std::make_unique<ReportCommand>(); }

}  // namespace indrive::cli
