// Evaluating snapshot files (the format itself is indrive/agent/snapshot_file.h): which actor
// of a snapshot acts, and how a file's architecture header sizes the evaluator's model.
#pragma once

#include <cstdint>
#include <filesystem>
#include <map>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "indrive/actor/eval_protocol.h"
#include "indrive/agent/agent_config.h"
#include "indrive/agent/snapshot_file.h"

namespace indrive::actor {

// Which actor of a snapshot acts: the exploration actor (zero-shot) or the task actor
// (few-shot).
enum class PolicyHead { kExploration, kTask };
// Resolves eval.head: "exploration", "task", or "auto" (exploration for eval_kind zero_shot,
// task for few_shot). Throws EvalError for anything else.
PolicyHead resolve_head(const std::string& head, const std::string& eval_kind);
// The parameter-group name of a head's actor ("expl_actor" or "task_actor").
const char* head_group(PolicyHead head);

// The snapshot file `given` names (eval.snapshot_file, --snapshot): a file as it is, or a run
// directory, which names the final-snapshot.params its learner wrote as the run ended. Throws
// EvalError for a directory without one, saying where snapshot files are.
std::filesystem::path snapshot_file_path(const std::filesystem::path& given);

// Throws EvalError naming `source`, the groups the snapshot holds and what to do, when the
// blob has no actor group for `head`.
void check_snapshot_head(std::span<const std::uint8_t> blob, PolicyHead head,
                         const std::string& source);

// Sizes `config` by a snapshot file's header, as evaluating that file needs: every size key,
// the preset name and the phase that `chosen` does not name are taken from the header.
// `chosen`: the agent keys the configuration chose explicitly, each with where ("preset" ->
// "--set preset=cpu", "world_model.deter" -> "preset 'cpu'";
// service::ServiceConfig::agent_choices()); a chosen "preset" counts as choosing every size. Throws
// EvalError naming `source`, each chosen size that differs from the file (both values and where it
// was chosen) and what to do. Returns a line for the log saying what was taken from the file; for a
// format-0 file (no header) it changes nothing and returns "".
std::string adopt_snapshot_architecture(agent::AgentConfig& config, const agent::SnapshotFile& file,
                                        const std::map<std::string, std::string>& chosen,
                                        const std::string& source);

}  // namespace indrive::actor
