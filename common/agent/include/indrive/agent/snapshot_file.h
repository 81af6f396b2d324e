// Snapshot files: a snapshot on disk is a small architecture header followed by the parameter
// blob of Agent::snapshot() (the bytes a PolicySnapshot carries in `params`: world model group
// with what acting runs, encoder and RSSM (older files hold the whole world model), then one
// actor group, "expl_actor" in pretraining or "task_actor" in finetune/dreamer, with a
// trailing CRC-32). The learner writes the policy it ends a run with as <run>/final-snapshot.params
// and the DDS evaluator the snapshot it evaluates as <run>/eval/snapshot-v<version>.params, so
// either can be evaluated again later without a learner and without naming its preset:
// `indrive-actor --evaluate --snapshot FILE`. The format lives here, beside the agent, because
// the learner writes it and the evaluators and tools read it; what evaluating a file means
// (which head acts, which sizes the file decides) is the actor's (indrive/actor/snapshot_file.h).
//
// File format 1 (little-endian; written by write_snapshot_file, read by read_snapshot_file):
//   "INDRSNAP"   8 bytes, the file magic
//   u32          file format version (kSnapshotFileFormat)
//   u32          N, length of the header text (at most 64 KiB)
//   N bytes      header text, one "key=value\n" line per snapshot_architecture_keys() entry:
//                preset, phase, actor (the blob's actor group), then the size keys; then,
//                when the writer knows them, the provenance keys run_id, version, env_steps
//                (readers of files without them, or of older builds, ignore them)
//   u32          CRC-32 of everything above
//   ...          the parameter blob, with its own trailing CRC-32
// Format 0, written before the header existed, is the bare blob (it starts with the blob magic
// "INNP"); it still loads, and its preset must then be given (--set preset=NAME).
//
#pragma once

#include <cstdint>
#include <filesystem>
#include <optional>
#include <span>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "indrive/agent/agent_config.h"

namespace indrive::agent {

// A snapshot file (or blob) is not what it claims; the message names the file and the fault.
class SnapshotFileError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// The parameter group of the actor that acts in `phase`: "expl_actor" in pretraining,
// "task_actor" in finetune and dreamer.
const char* acting_actor_group(Phase phase);

// Names of the parameter groups in a parameter blob, in order (no values are copied). Throws
// SnapshotFileError when the blob is not one (bad magic, truncated, checksum mismatch).
std::vector<std::string> snapshot_groups(std::span<const std::uint8_t> blob);

// The version of the snapshot file format that write_snapshot_file writes (0: bare blob).
inline constexpr std::uint32_t kSnapshotFileFormat = 1;

// The agent keys a snapshot file's header records, in order: "preset", "phase", "actor" (the
// actor group, not an agent key), then every size that decides the shapes of the world model
// and actor (world_model.image ... world_model.head_layers, behavior.units, behavior.layers).
const std::vector<std::string>& snapshot_architecture_keys();
// True for the keys of snapshot_architecture_keys() that are sizes (shape-deciding numbers).
bool is_snapshot_size_key(const std::string& key);
// The text `config` holds for an architecture key other than "actor" (as the header writes it).
std::string snapshot_key_text(const AgentConfig& config, const std::string& key);

// Where a snapshot came from, recorded after the architecture keys when known.
struct SnapshotProvenance {
  std::string run_id;
  std::uint64_t version = 0;    // the learner's policy version
  std::uint64_t env_steps = 0;  // env steps the learner had received when it made the snapshot
};

// A snapshot file's contents.
struct SnapshotFile {
  std::uint32_t format = 0;        // 0: a bare blob from before the header; else its version
  std::vector<std::uint8_t> blob;  // the parameter blob
  // The header's key=value pairs, in file order (empty for format 0).
  std::vector<std::pair<std::string, std::string>> architecture;

  // The header's value of `key` ("" when absent).
  std::string value(const std::string& key) const;
  // The provenance keys, when the header holds all three and they parse.
  std::optional<SnapshotProvenance> provenance() const;
};

// Reads a snapshot file of either format; throws SnapshotFileError naming the file when it is
// missing, empty, of an unknown format, or its header or blob is truncated, corrupt or
// incomplete.
SnapshotFile read_snapshot_file(const std::filesystem::path& path);
// Writes a snapshot file (format kSnapshotFileFormat) atomically: the header records the
// preset, phase and sizes of `architecture` (the agent config the blob was made with), the
// blob's actor group and, when given, `provenance`. Throws SnapshotFileError when the blob is not
// a parameter blob or its actor group is not the one of the config's phase.
void write_snapshot_file(const std::filesystem::path& path, std::span<const std::uint8_t> blob,
                         const AgentConfig& architecture,
                         const std::optional<SnapshotProvenance>& provenance = std::nullopt);

// What a snapshot file holds, for a person: its format, its header (preset, phase, actor,
// sizes, provenance), then per group the parameter count, values and bytes, and whether the
// world model is the part acting runs (snapshot_keeps) or the whole one of files written before.
std::string describe_snapshot_file(const SnapshotFile& file);
// Writes `file` with only what acting runs (snapshot_keeps), header unchanged, values bit
// for bit: what an older snapshot file of the whole world model becomes. Throws
// SnapshotFileError for a format-0 file (no header to keep: evaluate it with --set preset=NAME
// and let the evaluator save it again).
void write_acting_snapshot_file(const std::filesystem::path& path, const SnapshotFile& file);

}  // namespace indrive::agent
