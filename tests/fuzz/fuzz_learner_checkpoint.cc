// A learner checkpoint (learner.h: counters line, agent section, zstd replay section) resumed
// as Learner does: unpacked, its agent loaded, its replay restored.
#include <cstdint>

#include "fuzz_agent.h"
#include "fuzz_support.h"
#include "indrive/agent/agent.h"
#include "indrive/agent/replay.h"
#include "indrive/basics/run_dir.h"
#include "indrive/learner/learner.h"
#include "indrive/nn/serialize.h"

namespace {

using namespace indrive;

agent::ReplayOptions replay_options() {
  const auto config = fuzz::micro_agent();
  return {.capacity = config.replay.capacity,
          .height = config.world_model.image,
          .width = config.world_model.image,
          .seed = 1};
}

void make_seeds(const fuzz::fs::path& dir) {
  agent::Agent agent(fuzz::micro_agent());
  const auto agent_path = dir / "agent.tmp";
  agent.save_checkpoint(agent_path);
  const auto agent_bytes = read_file(agent_path);
  fuzz::fs::remove(agent_path);
  agent::ReplayBuffer replay(replay_options());
  for (int t = 0; t < 20; ++t) {
    agent::ReplayStep step;
    step.frame.assign(16 * 16, static_cast<std::uint8_t>(t % 8));
    step.action = t % 9;
    step.is_first = t == 0;
    replay.add(0, step);
  }
  const auto replay_path = dir / "replay.tmp";
  replay.save(replay_path);
  const auto replay_bytes = read_file(replay_path);
  fuzz::fs::remove(replay_path);
  const learner::LearnerCounters counters{
      .env_steps = 20, .updates = 3, .policy_version = 2, .learner_epoch = 1};
  fuzz::write_seed(dir, "with-replay",
                   learner::pack_checkpoint(counters, agent_bytes, replay_bytes));
  fuzz::write_seed(dir, "without-replay", learner::pack_checkpoint(counters, agent_bytes, {}));
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) { return fuzz::initialize(make_seeds); }

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static agent::Agent agent(fuzz::micro_agent());
  fuzz::accept<learner::CheckpointError, agent::AgentError, agent::ReplayError,
               nn::SerializationError>([&] {
    std::vector<std::uint8_t> agent_bytes, replay_bytes;
    learner::unpack_checkpoint(std::span(data, size), agent_bytes, &replay_bytes);
    agent.load_checkpoint(fuzz::as_file(agent_bytes.data(), agent_bytes.size(), ".agent"));
    if (!replay_bytes.empty()) {
      agent::ReplayBuffer replay(replay_options());
      replay.load(fuzz::as_file(replay_bytes.data(), replay_bytes.size(), ".replay"));
    }
  });
  return 0;
}
