// In-process training: one environment, the replay, the agent and its acting policy in one
// loop, with the same config as the distributed system. Used for debugging and end-to-end
// checks; the distributed learner runs the same Agent on chunks from actors.
//
//   MyEnv env;                                   // implements agent::Environment
//   LocalTrainer trainer(config, env, {.train_ratio = 32});
//   trainer.run(5000, [](const TrainMetrics& m) { log(m); });
//   trainer.save(run_dir / "checkpoints");
#pragma once

#include <atomic>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "indrive/agent/agent.h"
#include "indrive/agent/policy.h"
#include "indrive/agent/rate_limiter.h"
#include "indrive/agent/replay.h"

namespace indrive::agent {

// What an environment returns after reset or a step.
struct EnvStep {
  std::vector<std::uint8_t> frame;  // (H, W) class ids
  float reward = 0.0f;              // reward of arriving at this frame (0 after reset)
  bool is_last = false;             // the episode ended here
  bool is_terminal = false;         // it ended by a terminal event
};

// The minimal environment interface the local trainer drives.
class Environment {
 public:
  virtual ~Environment() = default;
  // Starts an episode and returns its first frame.
  virtual EnvStep reset() = 0;
  // Applies one of the 9 actions and returns the next frame.
  virtual EnvStep step(int action) = 0;
};

// Options of the local loop.
struct LocalTrainerOptions {
  double train_ratio = 32.0;  // replayed steps (batch * length per update) per env step
  int snapshot_every = 1;     // refresh the acting policy every this many updates
};

// Counters of the local loop.
struct LocalTrainerCounters {
  std::int64_t env_steps = 0;
  std::int64_t updates = 0;
  std::int64_t episodes = 0;
  double episode_return = 0.0;  // extrinsic return of the last finished episode
};

// Runs acting and training in one thread.
class LocalTrainer {
 public:
  // The environment must outlive the trainer. The replay keeps rewards only in task phases.
  LocalTrainer(const AgentConfig& config, Environment& env, LocalTrainerOptions options = {});
  // Takes `env_steps` environment steps (random during prefill, the policy afterwards) and
  // trains whenever the replay ratio allows; calls on_metrics after each update. Returns early,
  // between two updates or steps, once `stop` is set: the updates still owed (the catch-up after
  // the prefill is dozens) are trained by the next call, or after a resume.
  void run(std::int64_t env_steps,
           const std::function<void(const TrainMetrics&)>& on_metrics = nullptr,
           const std::atomic<bool>* stop = nullptr);
  // The env steps and updates of a resumed run's earlier sessions: the replay ratio is then kept
  // over the whole run, so updates a session still owed when it stopped (during a catch-up, for
  // one) are trained as soon as the replay allows. counters() stay this session's.
  void continue_from(std::int64_t env_steps, std::int64_t updates) {
    earlier_env_steps_ = env_steps;
    earlier_updates_ = updates;
  }
  // Writes agent.ckpt and replay.bin into `dir` (created if missing).
  void save(const std::filesystem::path& dir) const;
  // Restores agent.ckpt (and replay.bin when present and of this phase's reward mode).
  void load(const std::filesystem::path& dir);
  // Restores the agent from checkpoint bytes in memory (Agent::checkpoint_bytes; `name` for
  // errors) and acts with it.
  void load_agent(std::span<const std::uint8_t> bytes, const std::string& name);

  Agent& agent() { return agent_; }
  ReplayBuffer& replay() { return replay_; }
  const LocalTrainerCounters& counters() const { return counters_; }

 private:
  void refresh_policy();

  AgentConfig config_;
  Environment& env_;
  LocalTrainerOptions options_;
  RateLimiter rate_;  // the replay ratio as the learner keeps it (the prefill is the replay's)
  std::int64_t earlier_env_steps_ = 0, earlier_updates_ = 0;  // continue_from()
  Agent agent_;
  ReplayBuffer replay_;
  Policy policy_;
  RandomPolicy random_;
  PolicyState state_;
  EnvStep current_;
  bool need_reset_ = true;
  bool first_ = true;
  double return_ = 0.0;
  LocalTrainerCounters counters_;
};

}  // namespace indrive::agent
