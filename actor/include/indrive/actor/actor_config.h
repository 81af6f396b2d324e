// The actor folder's typed views of its run keys, each read once: ActorConfig for `actor.*`
// (training actors and evaluators alike) and EvalConfig for `eval.*`. The keys themselves
// (defaults, ranges, help) are declared with every other key of the run in
// common/service/src/run_config.cc (docs/architecture.md, section 5); a test checks that the
// defaults here are those.
//
//   const ActorConfig actor = actor_config(service.config());
//   SnapshotInbox inbox(run_id, descriptor, actor.request_after_s);
#pragma once

#include <string>
#include <vector>

#include "indrive/basics/config.h"

namespace indrive::actor {

struct ActorConfig {
  int chunk_length = 64;            // steps per TrajectoryChunk
  double heartbeat_s = 1.0;         // seconds between heartbeats
  double request_after_s = 2.0;     // an announced snapshot missing this long is re-requested
  double rejoin_after_s = 20.0;     // silence of the learner before a participant is replaced
  double rejoin_max_s = 160.0;      // longest wait between two replacements
  double coverage_period_s = 60.0;  // seconds between writes of coverage/actor-<id>.csv

  bool operator==(const ActorConfig&) const = default;
};

ActorConfig actor_config(const config::Config& config);

struct EvalConfig {
  // The grid.
  std::string towns = "town01,town02";  // comma-separated
  std::string routes = "all";           // comma-separated, or all
  std::vector<double> densities = {5, 10, 20};
  int episodes_per_cell = 50;
  // What drives, and for which table.
  std::string policy = "snapshot";  // snapshot, oracle or random
  std::string snapshot_file;        // empty: the learner's snapshots over DDS
  std::string head = "auto";        // auto, exploration or task
  std::string kind = "zero_shot";   // zero_shot or few_shot
  bool oracle_brake = true;
  double oracle_speed_mps = 5.0;
  // Which snapshot, and how long to wait for it.
  bool wait_for_done = true;
  double snapshot_timeout_s = 3600.0;
  double learner_silence_s = 120.0;
  bool continuous = false;
  int every_k = 1;
  bool resume = false;  // skip the episodes the results file holds for this evaluation
  // How an episode is judged (eval_protocol_episode.h).
  std::string protocol = "strict";  // strict or indrive_code
  int indrive_code_budget_steps = 30000;
  double budget_speed_mps = 3.0;
  double budget_slack = 1.5;
  int video_episodes = 0;
  // The route probe's settings (tools/route_probe/, indrive-route-probe).
  double probe_far_m = 14.0;
  double probe_near_m = 6.0;
  bool probe_oracle_brake = false;

  bool operator==(const EvalConfig&) const = default;
};

EvalConfig eval_config(const config::Config& config);

}  // namespace indrive::actor
