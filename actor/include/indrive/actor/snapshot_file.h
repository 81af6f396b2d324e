// Snapshot files: a snapshot on disk is a small architecture header followed by the parameter
// blob of Agent::snapshot() (the bytes a PolicySnapshot carries in `params`: world model group
// with what acting runs, encoder and RSSM (older files hold the whole world model), then one
// actor group, "expl_actor" in pretraining or "task_actor" in finetune/dreamer, with a
// trailing CRC-32). The DDS evaluator saves the snapshot it evaluates as
// <run>/eval/snapshot-v<version>.params, so it can be evaluated again later without a learner
// and without naming its preset: `indrive-actor --evaluate --snapshot FILE`.
//
// File format 1 (little-endian; written by write_snapshot_file, read by read_snapshot_file):
//   "INDRSNAP"   8 bytes, the file magic
//   u32          file format version (kSnapshotFileFormat)
//   u32          N, length of the header text (at most 64 KiB)
//   N bytes      header text, one "key=value\n" line per snapshot_architecture_keys() entry:
//                preset, phase, actor (the blob's actor group), then the size keys
//   u32          CRC-32 of everything above
//   ...          the parameter blob, with its own trailing CRC-32
// Format 0, written before the header existed, is the bare blob (it starts with the blob magic
// "INNP"); it still loads, and its preset must then be given (--set preset=NAME).
//
#pragma once

#include <cstdint>
#include <filesystem>
#include <map>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "indrive/actor/protocol.h"
#include "indrive/agent/agent_config.h"

namespace indrive::actor {

// Which actor of a snapshot acts: the exploration actor (zero-shot) or the task actor
// (few-shot).
enum class PolicyHead { kExploration, kTask };
// Resolves eval.head: "exploration", "task", or "auto" (exploration for eval_kind zero_shot,
// task for few_shot). Throws EvalError for anything else.
PolicyHead resolve_head(const std::string& head, const std::string& eval_kind);
// The parameter-group name of a head's actor ("expl_actor" or "task_actor").
const char* head_group(PolicyHead head);

// Names of the parameter groups in a parameter blob, in order (no values are copied). Throws
// EvalError when the blob is not one (bad magic, truncated, checksum mismatch).
std::vector<std::string> snapshot_groups(std::span<const std::uint8_t> blob);
// Throws EvalError naming `source`, the groups the snapshot holds and what to do, when the
// blob has no actor group for `head`.
void check_snapshot_head(std::span<const std::uint8_t> blob, PolicyHead head,
                         const std::string& source);
// The version of the snapshot file format that write_snapshot_file writes (0: bare blob).
inline constexpr std::uint32_t kSnapshotFileFormat = 1;

// The agent keys a snapshot file's header records, in order: "preset", "phase", "actor" (the
// actor group, not an agent key), then every size that decides the shapes of the world model
// and actor (world_model.image ... world_model.head_layers, behavior.units, behavior.layers).
const std::vector<std::string>& snapshot_architecture_keys();
// True for the keys of snapshot_architecture_keys() that are sizes (shape-deciding numbers).
bool is_snapshot_size_key(const std::string& key);

// A snapshot file's contents.
struct SnapshotFile {
  std::uint32_t format = 0;        // 0: a bare blob from before the header; else its version
  std::vector<std::uint8_t> blob;  // the parameter blob
  // The header's key=value pairs, in file order (empty for format 0).
  std::vector<std::pair<std::string, std::string>> architecture;

  // The header's value of `key` ("" when absent).
  std::string value(const std::string& key) const;
};

// Reads a snapshot file of either format; throws EvalError naming the file when it is missing,
// empty, of an unknown format, or its header or blob is truncated, corrupt or incomplete.
SnapshotFile read_snapshot_file(const std::filesystem::path& path);
// Writes a snapshot file (format kSnapshotFileFormat) atomically: the header records the
// preset, phase and sizes of `architecture` (the agent config the blob was made with) and the
// blob's actor group. Throws EvalError when the blob is not a parameter blob or its actor group
// is not the one of the config's phase.
void write_snapshot_file(const std::filesystem::path& path, std::span<const std::uint8_t> blob,
                         const agent::AgentConfig& architecture);

// What a snapshot file holds, for a person: its format, its header (preset, phase, actor,
// sizes), then per group the parameter count, values and bytes, and whether the world model is
// the part acting runs (agent::snapshot_keeps) or the whole one of files written before.
std::string describe_snapshot_file(const SnapshotFile& file);
// Writes `file` with only what acting runs (agent::snapshot_keeps), header unchanged, values bit
// for bit: what an older snapshot file of the whole world model becomes. Throws EvalError for a
// format-0 file (no header to keep: evaluate it with --set preset=NAME and let the evaluator
// save it again).
void write_acting_snapshot_file(const std::filesystem::path& path, const SnapshotFile& file);
// Sizes `config` by a snapshot file's header, as evaluating that file needs: every size key,
// the preset name and the phase that `chosen` does not name are taken from the header.
// `chosen`: the agent keys the configuration chose explicitly, each with where ("preset" ->
// "--set preset=cpu", "world_model.deter" -> "preset 'cpu'";
// service::ServiceConfig::agent_choices()); a chosen "preset" counts as choosing every size. Throws
// EvalError naming `source`, each chosen size that differs from the file (both values and where it
// was chosen) and what to do. Returns a line for the log saying what was taken from the file; for a
// format-0 file (no header) it changes nothing and returns "".
std::string adopt_snapshot_architecture(agent::AgentConfig& config, const SnapshotFile& file,
                                        const std::map<std::string, std::string>& chosen,
                                        const std::string& source);

}  // namespace indrive::actor
