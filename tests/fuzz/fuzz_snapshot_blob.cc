// A policy snapshot's parameter blob (nn/serialize.h) loaded into an acting policy, as every
// actor and evaluator does with the bytes of a PolicySnapshot or a snapshot file.
#include <cstdint>

#include "fuzz_agent.h"
#include "fuzz_support.h"
#include "indrive/agent/agent.h"
#include "indrive/agent/policy.h"
#include "indrive/nn/serialize.h"

namespace {

using namespace indrive;

void make_seeds(const fuzz::fs::path& dir) {
  fuzz::write_seed(dir, "pretrain", agent::Agent(fuzz::micro_agent()).snapshot());
  fuzz::write_seed(dir, "finetune",
                   agent::Agent(fuzz::micro_agent(agent::Phase::kFinetune)).snapshot());
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) { return fuzz::initialize(make_seeds); }

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static agent::Policy policy(fuzz::micro_agent());
  fuzz::accept<nn::SerializationError>(
      [&] { policy.load_snapshot(std::span<const std::uint8_t>(data, size)); });
  return 0;
}
