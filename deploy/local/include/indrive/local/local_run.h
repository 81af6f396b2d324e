// One training run in one process: the environment, the replay, the agent and its acting policy
// (agent::LocalTrainer on the real driving environment), with the run directory, config keys,
// checkpoints and metrics of the distributed learner, so that a local run can be resumed,
// plotted (`indrive plot`) and fine-tuned from exactly like a distributed one.
//
//   ServiceConfig config = ServiceConfig::resolve(options);   // --config, --run-dir, --set
//   LocalRun run(config);                                      // resumes from checkpoints/
//   run.on_progress([](const std::string& line) { std::puts(line.c_str()); });
//   run.train(stop_flag);        // until run.budget_env_steps or stop; checkpoints on exit
//   EvaluationSummary s = evaluate_locally(config, "straight", 10, stop_flag);
//
// Keys it reads besides the agent's: run.budget_env_steps, run.seed, env.* (town, route,
// densities, density_period_steps, time_limit_steps, coverage_segment_m), learner.replay_ratio,
// learner.log_interval_s, learner.checkpoint_minutes, learner.checkpoint_keep,
// learner.init_checkpoint (finetune: the pretraining checkpoint, a learner checkpoint or a bare
// agent checkpoint) and local.random (act randomly throughout, never train).
#pragma once

#include <atomic>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <stdexcept>
#include <string>

#include "indrive/agent/agent.h"
#include "indrive/envserver/coverage.h"
#include "indrive/service/run_config.h"

namespace indrive::local {

// A local run that cannot start: finetune without a checkpoint to start from, evaluation
// without a trained policy. The message says what to pass.
class LocalRunError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

class LocalRun {
 public:
  // Opens the run directory (writes config.yaml), loads the town, builds the agent, and resumes
  // from the newest checkpoint of the run, or (finetune) starts from learner.init_checkpoint.
  // Throws LocalRunError, config errors, agent::AgentError, the learner's CheckpointError or the
  // envserver's errors with what is wrong.
  // `config` is kept by reference and must outlive the run (a temporary is refused).
  explicit LocalRun(const service::ServiceConfig& config);
  explicit LocalRun(service::ServiceConfig&&) = delete;
  ~LocalRun();
  LocalRun(const LocalRun&) = delete;
  LocalRun& operator=(const LocalRun&) = delete;

  // Receives a console progress line every log interval.
  void on_progress(std::function<void(const std::string&)> callback);
  // Acts and trains until run.budget_env_steps env steps are done (0: no limit) or `stop` is
  // set; writes metrics.jsonl lines every learner.log_interval_s, a checkpoint every
  // learner.checkpoint_minutes and at the end, and coverage.csv (continued across resumes) at
  // the end. A run whose budget is already reached returns at once and rewrites nothing.
  void train(const std::atomic<bool>& stop);
  // Writes a checkpoint of the agent, replay and counters now (learner checkpoint format);
  // throws IoError when it cannot be written.
  void save_checkpoint();

  // Env steps of the whole run, resumed ones included.
  std::int64_t env_steps() const;
  // Training updates of the whole run, resumed ones included.
  std::int64_t updates() const;
  agent::Agent& agent();
  // Coverage of the run: this process's env steps plus those of the coverage.csv it resumed.
  const env::CoverageTracker& coverage() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// What a local evaluation found.
struct EvaluationSummary {
  int episodes = 0;
  int successes = 0;
  double success_rate = 0.0;           // successes / episodes
  double mean_route_completion = 0.0;  // 0..1
  double mean_steps = 0.0;
};

// Evaluates the acting policy of the run's newest checkpoint (sampled actions, or the most
// likely ones with agent.eval_sample=false; random actions when local.random is set) on `route`
// of env.town:
// `episodes` episodes per density of eval.densities with the protocol's traffic and spawn seeds
// (actor/eval_protocol.h). An episode succeeds when it reaches the route's destination without a
// failure event. Appends one row per episode to <run>/eval/local-<town>-<route>.csv, and records
// the first eval.video_episodes episodes of every density to <run>/videos/eval-*.mp4 (the
// evaluator's videos). Throws LocalRunError when the run has no checkpoint (and is not random).
EvaluationSummary evaluate_locally(const service::ServiceConfig& config, const std::string& route,
                                   int episodes, const std::atomic<bool>& stop);

}  // namespace indrive::local
