// `indrive untrained`: the snapshot file of an untrained agent, the control of evaluations.
#include <cstdio>

#include "command.h"
#include "indrive/agent/agent.h"
#include "indrive/agent/snapshot_file.h"

namespace indrive::cli {
namespace {

namespace fs = std::filesystem;

class UntrainedCommand final : public Command {
 public:
  CLI::App* add_to(CLI::App& app) override {
    auto* command = app.add_subcommand(
        "untrained",
        "write the snapshot file of an untrained agent (the initial random parameters of a "
        "preset): the control that shows what evaluations and the route probe give with "
        "nothing learned");
    command->add_option("--preset", preset_, "tiny, small or cpu")->capture_default_str();
    command->add_option("--seed", seed_, "initialisation seed")->capture_default_str();
    command->add_option("--out", out_, "snapshot file to write")->required();
    return command;
  }

  int run() override {
    agent::AgentConfig config = agent::preset(preset_);
    config.seed = seed_;
    config.replay.seed = seed_;
    const agent::Agent agent(config);
    agent::write_snapshot_file(out_, agent.snapshot(), config);
    std::printf("%s: %s", out_.c_str(),
                agent::describe_snapshot_file(agent::read_snapshot_file(out_)).c_str());
    return 0;
  }

 private:
  std::string preset_ = "tiny";
  std::uint64_t seed_ = 0;
  fs::path out_;
};

}  // namespace

std::unique_ptr<Command> untrained_command() { return std::make_unique<UntrainedCommand>(); }

}  // namespace indrive::cli
