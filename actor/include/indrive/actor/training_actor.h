// The training actor: one environment, the newest policy snapshot it holds (random actions
// until the first arrives), a TrajectoryChunk every L steps and at episode end, an
// EpisodeResult per episode and a Heartbeat, paced by the learner's StepAllowance.
//
//   service::ServiceConfig config = service::ServiceConfig::resolve(options);
//   TrainingActor actor(config, /*id=*/0);
//   actor.run(stop_flag);          // returns when stop_flag is set
#pragma once

#include <atomic>
#include <cstdint>
#include <memory>

#include "indrive/service/run_config.h"

namespace indrive::actor {

// What a training actor has done so far.
struct ActorStats {
  std::uint64_t env_steps = 0;  // recorded steps (frames), the unit of the StepAllowance
  std::uint64_t chunks = 0;
  std::uint64_t episodes = 0;
  std::uint64_t policy_version = 0;  // 0: random policy
  std::uint64_t snapshots_loaded = 0;
  std::uint64_t snapshots_rejected = 0;
  std::uint64_t snapshot_requests = 0;
  std::uint64_t rejoins = 0;  // DDS participants replaced after silence (actor.rejoin_after_s)
  double wait_s = 0.0;        // time spent waiting at the allowance
  double publish_s = 0.0;     // time spent compressing and writing chunks
  double total_s = 0.0;
};

class TrainingActor {
 public:
  // Sets up DDS (throws dds::DdsError) and the environment (throws the envserver's errors).
  // `config` is kept by reference and must outlive the actor (a temporary is refused).
  TrainingActor(const service::ServiceConfig& config, std::uint32_t id);
  TrainingActor(service::ServiceConfig&&, std::uint32_t) = delete;
  ~TrainingActor();
  TrainingActor(const TrainingActor&) = delete;
  TrainingActor& operator=(const TrainingActor&) = delete;

  // Steps episodes until `stop` becomes true; sends the open chunk's steps only when they end
  // an episode (a partial chunk is never sent).
  void run(const std::atomic<bool>& stop);
  const ActorStats& stats() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace indrive::actor
