// The learner's checkpoint file: what a restart resumes from, and what a finetune run and the
// local trainer start from. The files rotate in <run>/checkpoints/ (basics' CheckpointFiles).
#pragma once

#include <chrono>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <optional>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

#include "indrive/agent/agent.h"
#include "indrive/agent/replay.h"
#include "indrive/basics/run_dir.h"

namespace indrive::learner {

// A checkpoint of the learner could not be read (the message names the file and the fault).
class CheckpointError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Counters a checkpoint carries besides the agent, so that a restart continues them.
struct LearnerCounters {
  std::int64_t env_steps = 0;  // steps received and stored
  std::int64_t updates = 0;    // training steps done
  std::uint64_t policy_version = 0;
  std::uint64_t learner_epoch = 0;  // starts of the learner in this run
};

// A learner checkpoint (format version 3): a header line, the counters and section sizes as
// one JSON line, the agent's own checkpoint bytes, then the replay buffer's file
// (ReplayBuffer::save) compressed with zstd, so that a resumed learner trains on the data it had
// instead of refilling, and a fixed-size trailer "CRC32 <8 hex digits>\n" with the CRC-32 of
// every byte before it. `replay_bytes` may be empty (no replay section).
std::vector<std::uint8_t> pack_checkpoint(const LearnerCounters& counters,
                                          std::span<const std::uint8_t> agent_bytes,
                                          std::span<const std::uint8_t> replay_bytes = {});
// Splits a packed checkpoint into counters, agent bytes and (when `replay_bytes` is given) the
// decompressed replay file, empty when the checkpoint has none. Reads versions 1 (no replay
// section) and 2 (no trailer) too. Throws CheckpointError when the bytes are not a learner
// checkpoint or are truncated or damaged. Memory stays bounded by what the bytes hold: the
// replay section is never given more room than its zstd frame produces, whatever the damaged
// sizes of the counters line say.
LearnerCounters unpack_checkpoint(std::span<const std::uint8_t> bytes,
                                  std::vector<std::uint8_t>& agent_bytes,
                                  std::vector<std::uint8_t>* replay_bytes = nullptr);

// Writes a training run's checkpoints, for the learner and `indrive-train-local` alike: counters,
// agent and replay packed (pack_checkpoint) into <run>/checkpoints/, the newest `keep` kept. A
// write that fails (disk full, I/O error) is logged and counted but not thrown: atomic_write
// leaves the previous checkpoint as it was and no partial file, and the next checkpoint time
// tries again.
//
//   CheckpointWriter writer(run.checkpoints(), keep, "learner", checkpoint_s);
//   if (writer.seconds_since_save() >= checkpoint_s) writer.save(counters, agent, replay, steps);
class CheckpointWriter {
 public:
  // channel: the log channel; every_s: the checkpoint period (said in a failure's message).
  CheckpointWriter(std::filesystem::path folder, int keep, std::string channel, double every_s);

  // Writes one checkpoint (`replay_steps`: the steps `replay_bytes` holds, for the log line);
  // returns whether it was written. `final`: the one at exit, which has no next try.
  bool save(const LearnerCounters& counters, std::span<const std::uint8_t> agent_bytes,
            std::span<const std::uint8_t> replay_bytes, std::int64_t replay_steps,
            bool final = false);
  // The newest intact checkpoint this run wrote or resumed from (empty: none).
  const std::filesystem::path& latest() const { return latest_; }
  void resumed_from(std::filesystem::path file) { latest_ = std::move(file); }
  // Seconds since the last try (or since construction).
  double seconds_since_save() const;
  std::uint64_t written() const { return written_; }
  std::uint64_t failures() const { return failures_; }
  const CheckpointFiles& files() const { return files_; }

 private:
  CheckpointFiles files_;
  std::string channel_;
  double every_s_;
  std::filesystem::path latest_;
  std::uint64_t written_ = 0;
  std::uint64_t failures_ = 0;
  std::chrono::steady_clock::time_point last_try_ = std::chrono::steady_clock::now();
};

// A run restored from one checkpoint file.
struct RestoredRun {
  std::filesystem::path file;  // the checkpoint it came from
  LearnerCounters counters;
  std::unique_ptr<agent::Agent> agent;
  std::optional<agent::ReplayBuffer> replay;
  std::uint64_t skipped = 0;  // damaged newer checkpoints that were set aside
};

// Tries `files` (oldest first, as CheckpointFiles::list gives them) newest first and returns the
// first that restores completely, loaded into fresh objects: a file that fails half way (the
// agent loads its parameters before it checks its normalisers, for one) leaves nothing of
// itself behind. A damaged file is skipped with a warning, not fatal: a checkpoint cut short by a
// crash of the machine or a bit flip on disk should cost the run only the updates since the older
// one; the skipped newer files are renamed to <name>.damaged, out of the rotation. With none
// intact it throws CheckpointError listing each file and its fault, rather than let the run
// start again from nothing, which would silently throw away its training so far.
RestoredRun restore_newest(const std::vector<std::filesystem::path>& files,
                           const agent::AgentConfig& config,
                           const agent::ReplayOptions& replay_options, const std::string& run_id);

// The agent of one file that is either a learner checkpoint (its agent section and counters) or
// a bare agent checkpoint (Agent::checkpoint_bytes; zero counters), as a finetune's starting
// point and an evaluation read them, loaded into a fresh agent; no replay. Throws CheckpointError
// when the file is missing or is a damaged learner checkpoint, agent::AgentError when its agent
// does not load into `config`.
RestoredRun load_agent_checkpoint(const std::filesystem::path& file,
                                  const agent::AgentConfig& config);

// load_agent_checkpoint of the newest of `files` (oldest first) that loads. The damaged ones
// are skipped with a warning and left where they are (only a resuming run sets them aside);
// `skipped` counts them. Throws CheckpointError listing each file's fault when none loads.
RestoredRun load_newest_agent(const std::vector<std::filesystem::path>& files,
                              const agent::AgentConfig& config);

// Where a training run starts, for indrive-learner and indrive-train-local alike:
//   - its newest intact checkpoint among `files` (restore_newest: counters, agent, replay);
//   - else the agent of `init_checkpoint` when one is named (a learner checkpoint or a bare
//     agent checkpoint, as a finetune starts from a pretraining), with zero counters and no
//     replay;
//   - else nothing: counters zero, no agent, no replay.
// counters.learner_epoch is one more than the checkpoint's: this start counts. Throws
// CheckpointError when init_checkpoint does not exist or cannot be read, or when no checkpoint
// restores (restore_newest).
enum class StartedFrom { kCheckpoint, kInitCheckpoint, kNothing };
struct RunStart {
  StartedFrom from = StartedFrom::kNothing;
  RestoredRun restored;  // file: the checkpoint it came from (init_checkpoint for kInitCheckpoint)
};
RunStart start_run(const std::vector<std::filesystem::path>& files,
                   const std::string& init_checkpoint, const agent::AgentConfig& config,
                   const agent::ReplayOptions& replay_options, const std::string& run_id);

}  // namespace indrive::learner
