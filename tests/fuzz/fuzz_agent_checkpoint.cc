// An agent checkpoint (agent.h, save_checkpoint / load_checkpoint) read back into an agent, as
// a resuming learner or a finetune's learner.init_checkpoint does.
// Input: one flag byte, then the file. Flag bit 0 rewrites the file's CRC-32 trailer to match
// its content, so the parsing behind the checksum is explored too (a file written by another
// build, or damage the checksum misses, reaches it).
#include <cstdint>
#include <cstring>

#include "fuzz_agent.h"
#include "fuzz_support.h"
#include "indrive/agent/agent.h"
#include "indrive/basics/checksum.h"
#include "indrive/basics/run_dir.h"
#include "indrive/nn/serialize.h"

namespace {

using namespace indrive;

void make_seeds(const fuzz::fs::path& dir) {
  for (const auto phase : {agent::Phase::kPretrain, agent::Phase::kFinetune}) {
    agent::Agent agent(fuzz::micro_agent(phase));
    const auto path = dir / "checkpoint.tmp";
    agent.save_checkpoint(path);
    auto bytes = read_file(path);
    fuzz::fs::remove(path);
    bytes.insert(bytes.begin(), 0);
    fuzz::write_seed(dir, phase == agent::Phase::kPretrain ? "pretrain" : "finetune", bytes);
  }
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) { return fuzz::initialize(make_seeds); }

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 1) return 0;
  const std::vector<std::uint8_t> file = fuzz::file_with_flags(data, size);
  static agent::Agent agent(fuzz::micro_agent());
  const auto& path = fuzz::as_file(file.data(), file.size(), ".ckpt");
  fuzz::accept<agent::AgentError, nn::SerializationError>([&] { agent.load_checkpoint(path); });
  return 0;
}
