// Intrinsic reward modules of the pretraining phase, all on u_t = [h_t; s_t] with a
// stop-gradient into the world model, each with its own optimiser:
//   LD   (latent disagreement): K predictors of the next posterior's categorical probabilities
//        from [u_t, onehot(a_t)]; reward = disag_scale * mean over latent dims of the variance
//        across members.
//   ICM: inverse model CE(a_hat(u_t, u_{t+1}), a_t) and forward model ||u_hat_{t+1} - u_{t+1}||^2;
//        reward = eta * Norm(icm_scale * forward error).
//   RND: fixed random target f(u), trained predictor p(u); reward = Norm(rnd_scale * ||p - f||^2).
// The scales bring each raw signal to order 1 (config.h, IntrinsicConfig).
//
// The learner adds loss() to its total loss (one backward per step) and then calls step();
// rewards of imagined transitions come from reward(), which records no tape.
#pragma once

#include <memory>
#include <vector>

#include "indrive/agent/agent_config.h"
#include "indrive/agent/returns.h"
#include "indrive/nn/nn.h"

namespace indrive::agent {

// Replay transitions (u_t, a_t, u_{t+1}) built from a world-model pass, all stop-gradient.
struct Transitions {
  nn::Tensor feat;       // (N, feat) u_t
  nn::Tensor action;     // (N, 9) one-hot a_t, the action taken at step t
  nn::Tensor next_feat;  // (N, feat) u_{t+1}
  nn::Tensor next_post;  // (N, stoch * classes) posterior probabilities at t + 1
  nn::Tensor mask;       // (N, 1) 1 where step t + 1 continues the episode of step t
};

// Builds the (T - 1) * B transitions of a time-major batch. features is (T * B, feat),
// post_probs (T * B, S), actions (T * B, 9) one-hot of the action taken at each step, is_first
// (T * B, 1). Applies stop_gradient to everything, so intrinsic losses cannot reach the model.
Transitions make_transitions(nn::Tensor features, nn::Tensor post_probs, nn::Tensor actions,
                             nn::Tensor is_first, int batch);

// Common interface of LD, ICM and RND.
class IntrinsicModule {
 public:
  virtual ~IntrinsicModule() = default;
  // The training loss on replay transitions (a recorded scalar); it only reaches params().
  virtual nn::Tensor loss(const Transitions& batch) = 0;
  // Intrinsic rewards (N) of imagined transitions, without a tape. feat and next_feat are
  // (N, feat), action (N, 9). Normalising modules update their running moments here.
  virtual std::vector<float> reward(nn::Tensor feat, nn::Tensor action, nn::Tensor next_feat) = 0;
  // Clips and applies the module's own Adam update (after the learner's backward).
  nn::StepStats step() { return optimizer_->step(); }
  // The trained parameters.
  nn::ParamGroup& params() { return params_; }
  // Every parameter group the module holds (trained and fixed), for checkpoints.
  virtual std::vector<nn::ParamGroup*> groups() { return {&params_}; }
  nn::Adam& optimizer() { return *optimizer_; }
  // Normaliser state for checkpoints (empty when the module has none).
  virtual std::vector<float> normalizer_state() const { return {}; }
  virtual void set_normalizer_state(std::span<const float> state) { (void)state; }
  // Value of the last loss() terms, for metrics.
  float last_loss() const { return last_loss_; }
  // Mean raw signal of the last reward() call (LD: variance or std; ICM: forward error; RND:
  // prediction error), before the module's scale and normaliser, for metrics.
  float last_raw_reward() const { return last_raw_reward_; }
  // Standard deviation of that raw signal over the call's transitions: the spread that tells
  // imagined actions apart, and what the ICM and RND normaliser's eps is compared with.
  float last_raw_std() const { return last_raw_std_; }

 protected:
  explicit IntrinsicModule(const IntrinsicConfig& config);
  void make_optimizer();

  IntrinsicConfig config_;
  nn::ParamGroup params_{"intrinsic"};
  std::unique_ptr<nn::Adam> optimizer_;
  float last_loss_ = 0.0f;
  float last_raw_reward_ = 0.0f;
  float last_raw_std_ = 0.0f;
  // Records the mean and spread of the raw signal and multiplies it by `scale` in place.
  void scale_raw(std::vector<float>& raw, float scale);
};

// The module of `config.method`.
std::unique_ptr<IntrinsicModule> make_intrinsic(const IntrinsicConfig& config,
                                                const WorldModelConfig& model, nn::Rng& rng);

}  // namespace indrive::agent
