// A snapshot file as `indrive-actor --evaluate --snapshot FILE` takes it: header and blob read,
// the agent sized by the header, the blob loaded into a policy of that size.
#include <cstdint>

#include "fuzz_agent.h"
#include "fuzz_support.h"
#include "indrive/actor/snapshot_file.h"
#include "indrive/agent/agent.h"
#include "indrive/agent/policy.h"
#include "indrive/agent/snapshot_file.h"
#include "indrive/nn/serialize.h"

namespace {

using namespace indrive;

void make_seeds(const fuzz::fs::path& dir) {
  const auto config = fuzz::micro_agent();
  const auto blob = agent::Agent(config).snapshot();
  agent::write_snapshot_file(dir / "format1", blob, config);
  fuzz::write_seed(dir, "format0", blob);  // a bare blob from before the header
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) { return fuzz::initialize(make_seeds); }

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const auto& path = fuzz::as_file(data, size, ".params");
  fuzz::accept<actor::EvalError, agent::SnapshotFileError, agent::AgentConfigError,
               nn::SerializationError>([&] {
    const agent::SnapshotFile file = agent::read_snapshot_file(path);
    agent::AgentConfig config = fuzz::micro_agent();
    actor::adopt_snapshot_architecture(config, file, {}, path.string());
    agent::validate(config);
    agent::Policy policy(config);
    policy.load_snapshot(file.blob);
  });
  return 0;
}
