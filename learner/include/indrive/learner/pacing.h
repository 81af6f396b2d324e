// The learner's pacing of its actors (docs/architecture.md, section 4): the StepAllowance (how
// many env steps the run allows in all) whenever it changes, and the learner's heartbeat (how
// many steps have arrived, the policy version, whether the run is done) with it, at least every
// 100 ms. Actors estimate the run's steps as the heartbeat's count plus their own since
// (actor::AllowanceGate), so the count goes out only after the chunks that arrived during an
// update are drained: an older count would let each actor take its in-flight steps twice.
//
//   Pacer pacer(endpoints, run_id);
//   pacer.publish({.allowed = ..., .env_steps = ..., ...}, /*force=*/false);  // each loop turn
#pragma once

#include <chrono>
#include <cstdint>
#include <string>

#include "indrive/dds/messages.h"
#include "indrive/dds/participant.h"

namespace indrive::learner {

// What the pacing messages say.
struct PacingState {
  std::uint64_t allowed = 0;   // the run's allowance of env steps, all actors together
  std::int64_t env_steps = 0;  // received so far
  std::int64_t updates = 0;
  std::uint64_t policy_version = 0;
  std::uint64_t learner_epoch = 0;
  double replay_ratio = 0.0;
  std::uint64_t dropped_chunks = 0;
  bool done = false;  // the budget is reached
};

class Pacer {
 public:
  // Creates the allowance and heartbeat writers on `endpoints` (which outlive the pacer's use).
  Pacer(dds::EndpointSet& endpoints, std::string run_id);

  // Writes both messages when `force`, when the allowance or the received count changed (at
  // most every 5 ms), or when the last went out 100 ms ago or more; else nothing. Returns
  // whether it wrote.
  bool publish(const PacingState& state, bool force);

 private:
  std::string run_id_;
  dds::Writer<msg::StepAllowance>& allowances_;
  dds::Writer<msg::Heartbeat>& heartbeats_;
  std::uint64_t published_allowance_ = 0;
  std::int64_t published_received_ = -1;
  std::chrono::steady_clock::time_point last_{};
};

}  // namespace indrive::learner
