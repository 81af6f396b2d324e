// Actor-critic trained in imagination (DreamerV3): from every posterior state of a batch, the
// actor rolls H steps through the world model's prior; lambda-returns of the given rewards
// train a two-hot critic (with a slow EMA critic as regulariser) and a REINFORCE actor over the
// 9 discrete actions with an entropy bonus; both losses are weighted by the cumulative
// discount. The rollout records no tape, so no loss here reaches the world model.
//
//   ActorCritic ac("expl", config.behavior, config.world_model.feat_dim(), rng);
//   ImaginedTrajectory traj = ac.imagine(wm, start, rng);
//   std::vector<float> r = intrinsic.reward(...);        // (H * N) for the H transitions
//   nn::Tensor loss = ac.loss(traj, r, &metrics);
//   graph.backward(loss); ac.step();
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "indrive/agent/agent_config.h"
#include "indrive/agent/returns.h"
#include "indrive/agent/world_model.h"
#include "indrive/nn/nn.h"

namespace indrive::agent {

// An imagined rollout of H steps from N start states (no tape).
struct ImaginedTrajectory {
  int horizon = 0, n = 0;
  nn::Tensor features;      // ((H + 1) * N, feat): u_0 .. u_H, row t * N + i
  nn::Tensor actions;       // (H * N, 9) one-hot a_t taken at u_t
  std::vector<float> cont;  // (H * N) continuation probability of the transition t -> t + 1
  // (N) continuation of each start state, 1 - is_terminal of its replay step (DreamerV3 weights
  // the first imagined step by it, so a rollout from a terminal state teaches nothing); empty
  // means every start continues.
  std::vector<float> start_cont;
  // u_t rows [t * N, (t + 1) * N) and u_{t+1}, as views for reward computation.
  nn::Tensor state_features() const;  // (H * N, feat) u_0 .. u_{H-1}
  nn::Tensor next_features() const;   // (H * N, feat) u_1 .. u_H
};

// fn(part), one value per row, over every row of x (rows, d) without a tape, in fixed chunks
// of rows side by side on the engine's threads (nn::parallel_tasks): whole chunks need no
// barrier between their ops, where split op by op a thread descheduled by another job held
// every op, and fixed chunks keep the values the same for any thread count. fn reads only
// parameters and its part, e.g. [&](Tensor u) { return nn::twohot_mean(critic(u)); }.
std::vector<float> row_values(nn::Tensor x, const std::function<nn::Tensor(nn::Tensor)>& fn);

// Metrics of one actor-critic loss.
struct BehaviorMetrics {
  float actor_loss = 0, critic_loss = 0, entropy = 0, return_mean = 0, reward_mean = 0;
  float return_scale = 0;
  float value_mean = 0;  // the critic's mean value of the H * N imagined states
};

// One actor and one critic (with its slow copy), e.g. the exploration or the task behaviour.
// Groups: "<prefix>_actor", "<prefix>_critic", "<prefix>_slow_critic".
class ActorCritic {
 public:
  // Features are (N, feat_dim); where their columns from `one_hot_from` on are one-hot (a world
  // model's [deter, stoch], one_hot_from = deter), the first layers gather instead of multiply.
  ActorCritic(const std::string& prefix, const BehaviorConfig& config, int feat_dim, nn::Rng& rng,
              int one_hot_from = -1);
  ActorCritic(const ActorCritic&) = delete;
  ActorCritic& operator=(const ActorCritic&) = delete;

  // Action probabilities (N, 9) with the 1% uniform mix, from features (N, feat).
  nn::Tensor action_probs(nn::Tensor features);
  // Start states per chunk of the imagined rollout: chunks run side by side, one per thread,
  // each with its own random stream, so the trajectory does not depend on the thread count.
  static constexpr std::int64_t kImagineChunkRows = 64;

  // Rolls the actor through the prior for H steps from `start` (N rows, stop-gradient), in
  // chunks of kImagineChunkRows start states on the engine's threads. start_cont (N, or empty)
  // is the start states' continuation, kept in the trajectory.
  ImaginedTrajectory imagine(WorldModel& wm, const RssmState& start, nn::Rng& rng,
                             std::vector<float> start_cont = {});
  // Actor + critic loss (a recorded scalar) of a trajectory and its rewards (H * N), reward
  // t belonging to the transition u_t -> u_{t+1}. Updates the return normaliser.
  nn::Tensor loss(const ImaginedTrajectory& traj, const std::vector<float>& rewards,
                  BehaviorMetrics* metrics = nullptr);
  // Applies the actor and critic Adam updates and moves the slow critic.
  void step();
  // Copies another behaviour's actor parameters into this actor (task actor initialisation).
  void copy_actor_from(const ActorCritic& other);

  nn::ParamGroup& actor_params() { return actor_params_; }
  nn::ParamGroup& critic_params() { return critic_params_; }
  nn::ParamGroup& slow_critic_params() { return slow_params_; }
  nn::Adam& actor_optimizer() { return *actor_opt_; }
  nn::Adam& critic_optimizer() { return *critic_opt_; }
  ReturnNormalizer& return_normalizer() { return return_norm_; }
  const BehaviorConfig& config() const { return config_; }

 private:
  BehaviorConfig config_;
  nn::ParamGroup actor_params_;
  nn::ParamGroup critic_params_;
  nn::ParamGroup slow_params_;
  nn::Mlp actor_;
  nn::Mlp critic_;
  nn::Mlp slow_critic_;
  std::unique_ptr<nn::Adam> actor_opt_;
  std::unique_ptr<nn::Adam> critic_opt_;
  std::unique_ptr<nn::Ema> slow_update_;
  ReturnNormalizer return_norm_;
};

}  // namespace indrive::agent
