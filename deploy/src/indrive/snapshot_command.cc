// `indrive snapshot`: what a snapshot file holds; with --acting-only, the file without the
// parameters acting does not run.
#include <cstdio>

#include "command.h"
#include "indrive/agent/snapshot_file.h"

namespace indrive::cli {
namespace {

namespace fs = std::filesystem;

class SnapshotCommand final : public Command {
 public:
  CLI::App* add_to(CLI::App& app) override {
    auto* command = app.add_subcommand(
        "snapshot",
        "say what a snapshot file holds (architecture, groups, sizes); with --acting-only, "
        "write it without the parameters acting does not run (an older file of the whole world "
        "model)");
    command
        ->add_option("file", file_,
                     "snapshot file (<run>/snapshot.params, <run>/eval/snapshot-v<N>.params)")
        ->required()
        ->check(CLI::ExistingFile);
    command->add_option("--acting-only", acting_out_,
                        "write the file with only what acting runs (encoder, RSSM, actor) here");
    return command;
  }

  int run() override {
    const auto file = agent::read_snapshot_file(file_);
    std::printf("%s: %s", file_.c_str(), agent::describe_snapshot_file(file).c_str());
    if (!acting_out_.empty()) {
      agent::write_acting_snapshot_file(acting_out_, file);
      std::printf("%s: %s", acting_out_.c_str(),
                  agent::describe_snapshot_file(agent::read_snapshot_file(acting_out_)).c_str());
    }
    return 0;
  }

 private:
  fs::path file_;
  fs::path acting_out_;
};

}  // namespace

std::unique_ptr<Command> snapshot_command() { return std::make_unique<SnapshotCommand>(); }

}  // namespace indrive::cli
