// Helpers of the actor's evaluation tests (policies, snapshot files, protocol records).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "indrive/actor/eval_protocol.h"
#include "indrive/agent/agent.h"
#include "indrive/agent/snapshot_file.h"

namespace indrive::actor::test_support {

// The message of the EvalError (or, from the snapshot file format, SnapshotFileError) `body`
// throws ("" when it throws nothing).
template <typename F>
std::string eval_error_of(F&& body) {
  try {
    body();
  } catch (const EvalError& error) {
    return error.what();
  } catch (const agent::SnapshotFileError& error) {
    return error.what();
  }
  return "";
}

inline std::vector<std::uint8_t> tiny_snapshot(agent::Phase phase) {
  agent::AgentConfig config = agent::preset("tiny");
  config.phase = phase;
  agent::Agent agent(config);
  return agent.snapshot();
}

}  // namespace indrive::actor::test_support
