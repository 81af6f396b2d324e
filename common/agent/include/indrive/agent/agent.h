// The learner's agent: world model, intrinsic module, exploration and task actor-critics, their
// optimisers and normalisers, trained per phase with the freezing rules of the method:
//   pretrain  world model + intrinsic module + exploration actor-critic on r_int; the batch must
//             carry no reward.
//   finetune  world model, intrinsic module and exploration actor-critic frozen (never stepped);
//             the reward head (on stop-gradient features) and the task actor-critic train on
//             r_ext. The task actor starts as a copy of the exploration actor, with a fresh critic.
//   dreamer   world model + reward head + task actor-critic from scratch on r_ext.
// Acting lives in Policy (policy.h), which needs only snapshot() bytes.
//
//   Agent agent(config);
//   TrainMetrics m = agent.train_step(replay.sample(config.replay.batch, config.replay.length));
//   publish(agent.snapshot());
//   agent.save_checkpoint(run_dir / "checkpoints" / "latest.ckpt");
#pragma once

#include <cstdint>
#include <filesystem>
#include <memory>
#include <span>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "indrive/agent/agent_config.h"
#include "indrive/agent/behavior.h"
#include "indrive/agent/intrinsic.h"
#include "indrive/agent/precision_choice.h"
#include "indrive/agent/replay.h"
#include "indrive/agent/world_model.h"

namespace indrive::agent {

// A use of the agent that the data or files do not allow (reward in a pretraining batch,
// missing reward in a task batch, unreadable or mismatched checkpoint).
class AgentError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Named scalars of one training step, in a stable order.
using TrainMetrics = std::vector<std::pair<std::string, float>>;

// Wall seconds of the stages of one train_step: where an update's time goes. Kept apart from
// TrainMetrics, which depend only on the data, parameters and RNG (bitwise reproducible).
struct StepTiming {
  double world_model = 0;  // observe: encoder, RSSM over the batch, decoder, heads, losses
  double intrinsic = 0;    // the intrinsic module's loss on replay transitions (pretrain only)
  double imagine = 0;      // rollouts of the horizon through the prior with the acting policy
  double reward = 0;       // rewards of the imagined transitions (intrinsic or reward head)
  double behavior = 0;     // actor-critic losses: critics, lambda-returns, REINFORCE
  double backward = 0;     // the one backward pass for all losses
  double optimizers = 0;   // optimiser steps of the parts that train in the phase

  double total() const {
    return world_model + intrinsic + imagine + reward + behavior + backward + optimizers;
  }
  // As "time/<stage>_s" metrics (and "time/update_s" for the sum).
  TrainMetrics as_metrics() const;
};

// Everything the learner holds for training.
class Agent {
 public:
  // Builds all parts from config (validated; throws AgentConfigError). In finetune, call
  // load_checkpoint with a pretrained checkpoint before training.
  explicit Agent(const AgentConfig& config);

  // One update of the parts that train in the current phase on a replay batch.
  TrainMetrics train_step(const SequenceBatch& batch);
  // Switches the phase. Entering finetune or dreamer from pretrain initialises the task
  // actor from the exploration actor (finetune) and keeps the fresh task critic.
  void set_phase(Phase phase);
  Phase phase() const { return config_.phase; }
  const AgentConfig& config() const { return config_; }
  std::int64_t train_steps() const { return train_steps_; }
  // The precision of the products and how it was chosen (config.precision; "auto" measures).
  const PrecisionChoice& precision_choice() const { return precision_; }
  // Stage timing of the last train_step.
  const StepTiming& last_timing() const { return timing_; }
  // The matrix-product FLOPs of each stage of the last update (nn::gemm_flops; the same
  // fields as last_timing, in FLOPs): what the benchmark divides by the seconds.
  const StepTiming& last_flops() const { return flops_; }

  // Parameters actors need (the world model's encoder and RSSM, and the acting actor), as a
  // serialized blob (snapshot_keeps in policy.h says which).
  std::vector<std::uint8_t> snapshot() const;
  // Name of the actor group that acts in the current phase ("expl_actor" or "task_actor").
  std::string acting_actor_group() const;

  // Writes parameters, optimiser states, normalisers, counters and the RNG state, atomically.
  // Throws AgentError when the file cannot be written.
  void save_checkpoint(const std::filesystem::path& path) const;
  // Restores a checkpoint of a model of the same sizes; the phase of this agent is kept (so a
  // pretrain checkpoint can start a finetune). Throws AgentError when the file is missing,
  // corrupt, or of another architecture.
  void load_checkpoint(const std::filesystem::path& path);
  // The bytes save_checkpoint writes and load_checkpoint reads, in memory: the learner packs
  // them into its own checkpoint file, so no staging file is written (and none is left behind
  // when the disk is full). `name` names where the bytes came from in error messages. A failed
  // load may leave the agent partly overwritten: load into a fresh agent when that matters.
  std::vector<std::uint8_t> checkpoint_bytes() const;
  void load_checkpoint(std::span<const std::uint8_t> bytes, const std::string& name);

  WorldModel& world_model() { return *wm_; }
  IntrinsicModule& intrinsic() { return *intrinsic_; }
  ActorCritic& exploration() { return *expl_; }
  ActorCritic& task() { return *task_; }
  // Every parameter group, in checkpoint order.
  std::vector<nn::ParamGroup*> groups();

 private:
  class StageClock;  // times the stages of one update (agent.cc)

  std::vector<const nn::ParamGroup*> groups() const;
  std::vector<nn::Adam*> optimizers() const;

  // The stages of train_step(), in order.
  void check_batch(const SequenceBatch& batch) const;
  bool trains_world_model() const;
  // The world model's loss (or, frozen, the reward and continuation heads') onto `losses`.
  WorldModelOutput world_model_loss(const SequenceBatch& batch, std::vector<nn::Tensor>& losses,
                                    TrainMetrics& metrics);
  nn::Tensor intrinsic_loss(const SequenceBatch& batch, const WorldModelOutput& out,
                            TrainMetrics& metrics);
  ImaginedTrajectory imagine_from(const SequenceBatch& batch, const WorldModelOutput& out,
                                  ActorCritic& behavior);
  // Task phases: the reward head's; pretraining: the intrinsic module's.
  std::vector<float> imagined_rewards(const ImaginedTrajectory& traj, TrainMetrics& metrics);
  void backward_and_step(const std::vector<nn::Tensor>& losses, ActorCritic& behavior,
                         TrainMetrics& metrics, StageClock& clock);

  AgentConfig config_;
  nn::Rng rng_;
  std::unique_ptr<WorldModel> wm_;
  std::unique_ptr<IntrinsicModule> intrinsic_;
  std::unique_ptr<ActorCritic> expl_;
  std::unique_ptr<ActorCritic> task_;
  std::unique_ptr<nn::Adam> wm_opt_;
  std::unique_ptr<nn::Adam> reward_opt_;
  std::unique_ptr<nn::Adam> cont_opt_;  // the continuation head alone (agent.finetune_cont)
  std::int64_t train_steps_ = 0;
  bool task_actor_initialised_ = false;
  StepTiming timing_;
  StepTiming flops_;
  PrecisionChoice precision_;
};

}  // namespace indrive::agent
