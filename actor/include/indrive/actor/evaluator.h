// The evaluator: an actor in evaluation mode. It runs its share of the protocol grid
// (eval_protocol.h), one protocol episode at a time (eval_protocol_episode.h), with one policy
// source (policies.h) and writes one CSV row (and, when it evaluates a learner's snapshot, one
// EpisodeResult on DDS) per episode.
//
// Policy sources (eval.policy, or indrive-actor --policy):
//   snapshot  the learner's snapshot over DDS (by default its last one, once the learner reports
//             done), or a snapshot file (eval.snapshot_file / --snapshot FILE) without DDS,
//             whose header sizes the model and camera unless the config chose the sizes.
//             Zero-shot runs the exploration actor, few-shot the task actor (eval.head).
//   oracle    the route follower with the 9 actions; eval.oracle_brake coasts behind a leader.
//   random    uniform actions.
// Step budget: every episode gets route_step_budget(route length, eval.budget_speed_mps,
// eval.budget_slack) steps (default 5 steps per metre: the route at 3 m/s with 1.5x slack),
// replacing env.time_limit_steps; running out is the failure "time_limit".
// Videos: the first eval.video_episodes episodes of every cell are recorded to
// <run>/videos/eval-<town>-<route>-<density>-<episode>.mp4 (camera | bird's-eye view, step,
// speed, route progress, and the events in a red band when they fire).
// Continuous mode (eval.continuous, --continuous): evaluates the first snapshot, then every
// snapshot at least eval.every_k versions newer, and the learner's final one, appending rows
// with the snapshot version and env steps to <run>/eval/curve-<index>.csv (a learning curve;
// `indrive report` leaves those files alone).
//
//   Evaluator evaluator(config, /*index=*/0, /*count=*/1);
//   int code = evaluator.run(stop_flag);   // 0 when its episodes are done
#pragma once

#include <atomic>
#include <filesystem>
#include <memory>
#include <string>

#include "indrive/actor/eval_protocol.h"
#include "indrive/service/run_config.h"

namespace indrive::actor {

// The grid the config's eval.* keys describe. Throws std::invalid_argument when it is invalid
// and EvalError for an unknown town or route.
ProtocolGrid protocol_grid(const config::Config& config);

// The header of a learning-curve file (eval/curve-<index>.csv).
const std::string& curve_csv_header();

class Evaluator {
 public:
  // Checks the inputs (grid names, policy source, head, snapshot file) and sets up the
  // environment, and DDS only when a learner's snapshot is evaluated. Throws EvalError,
  // dds::DdsError or the envserver's errors with what is wrong.
  // `config` is kept by reference and must outlive the evaluator (a temporary is refused).
  Evaluator(const service::ServiceConfig& config, int index, int count);
  Evaluator(service::ServiceConfig&&, int, int) = delete;
  ~Evaluator();
  Evaluator(const Evaluator&) = delete;
  Evaluator& operator=(const Evaluator&) = delete;

  // Runs the episodes; returns 0 when all ran (or when stopped, with a partial file), 2 when no
  // snapshot came within eval.snapshot_timeout_s. Throws EvalError when a learner's snapshot
  // lacks the head to evaluate.
  int run(const std::atomic<bool>& stop);

  // The results file this evaluator appends to (eval/evaluator-<index>.csv).
  std::filesystem::path results_file() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace indrive::actor
