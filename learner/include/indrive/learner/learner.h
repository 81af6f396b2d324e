// The learner process: receives chunks, keeps replay, trains the agent at the configured
// replay ratio, publishes versioned policy snapshots, the step allowance, announces and
// heartbeats, logs metrics and checkpoints so that a restart resumes the run.
//
//   ServiceConfig config = ServiceConfig::resolve(options);
//   Learner learner(config);                          // resumes from the newest checkpoint
//   learner.on_progress([](const std::string& line) { std::puts(line.c_str()); });
//   int code = learner.run(stop_flag);                // until the budget or stop_flag
#pragma once

#include <atomic>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "indrive/learner/checkpoint.h"
#include "indrive/service/run_config.h"

namespace indrive::learner {

// What the learner has done, readable after run().
struct LearnerStats {
  LearnerCounters counters;
  std::uint64_t chunks = 0;
  std::uint64_t dropped_chunks = 0;
  std::uint64_t sequence_gaps = 0;  // chunks whose predecessor of the same actor never came
  std::uint64_t snapshots_published = 0;
  std::uint64_t snapshot_requests = 0;  // republished on a late joiner's SnapshotRequest
  std::uint64_t episodes = 0;
  std::uint64_t failed_updates = 0;
  std::int64_t restored_replay_steps = 0;  // replay steps restored from the checkpoint
  std::filesystem::path resumed_from;      // the checkpoint the learner resumed from, if any
  // Damaged checkpoints, newer than resumed_from, that the resume skipped (and set aside).
  std::uint64_t skipped_checkpoints = 0;
};

class Learner {
 public:
  // Opens the run directory (writes config.yaml), builds the agent and replay, resumes from
  // the newest checkpoint that restores completely (damaged newer ones are logged, skipped and
  // renamed to <name>.damaged), and sets up DDS. Throws CheckpointError listing each file and
  // its fault when there are checkpoints but none restores, and agent::AgentError,
  // dds::DdsError or IoError with what is wrong.
  // `config` is kept by reference and must outlive the learner (a temporary is refused).
  explicit Learner(const service::ServiceConfig& config);
  explicit Learner(service::ServiceConfig&&) = delete;
  ~Learner();
  Learner(const Learner&) = delete;
  Learner& operator=(const Learner&) = delete;

  // Receives a console progress line every log interval (the executable prints it).
  void on_progress(std::function<void(const std::string&)> callback);
  // Trains until the env-step budget is reached or `stop` is set, then checkpoints and returns
  // 0, or 1 when that final checkpoint could not be written (the log names the file and why).
  // A periodic checkpoint that cannot be written is logged and counted (checkpoint_failures)
  // and tried again at the next checkpoint time; training goes on.
  int run(const std::atomic<bool>& stop);
  const LearnerStats& stats() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace indrive::learner
