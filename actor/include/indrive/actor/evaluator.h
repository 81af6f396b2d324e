// The evaluator: an actor in evaluation mode. It waits for a policy snapshot (by default the
// learner's last one, announced when the learner reports it is done), freezes it, runs its share
// of the protocol grid (protocol.h) and writes one CSV row and one EpisodeResult per episode.
//
//   Evaluator evaluator(config, /*index=*/0, /*count=*/1);
//   int code = evaluator.run(stop_flag);   // 0 when its episodes are done
#pragma once

#include <atomic>
#include <memory>

#include "indrive/actor/protocol.h"
#include "indrive/actor/service_config.h"

namespace indrive::actor {

// The grid the config's eval.* keys describe. Throws std::invalid_argument when it is invalid.
ProtocolGrid protocol_grid(const config::Config& config);

class Evaluator {
 public:
  // Sets up DDS and the environment; throws dds::DdsError or the envserver's errors.
  Evaluator(const ServiceConfig& config, int index, int count);
  ~Evaluator();
  Evaluator(const Evaluator&) = delete;
  Evaluator& operator=(const Evaluator&) = delete;

  // Waits for the snapshot to evaluate, then runs the episodes; returns 0 when all ran, 2 when
  // no snapshot came within eval.snapshot_timeout_s, 0 with a partial file when stopped.
  int run(const std::atomic<bool>& stop);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace indrive::actor
