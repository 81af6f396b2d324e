// The DreamerV3 world model (2023 "v1" layout): conv encoder, RSSM with 32x32 categorical
// latents, transposed-conv decoder, continuation head, and the reward head of task phases.
//
// Tensors are time-major: a batch of B sequences of T steps is flattened to T * B rows, row
// t * B + b holding step t of sequence b, so that one time step is a contiguous slice.
//
//   WorldModel wm(config.world_model, rng);
//   nn::current_graph().reset();
//   WorldModelOutput out = wm.observe(batch, /*with_reward=*/false, sample_rng);
//   nn::current_graph().backward(out.loss);
#pragma once

#include <cstddef>
#include <vector>

#include "indrive/agent/agent_config.h"
#include "indrive/agent/replay.h"
#include "indrive/nn/nn.h"

namespace indrive::agent {

// RSSM state of N rows: deterministic h and stochastic s (one-hot per latent group).
struct RssmState {
  nn::Tensor deter;  // (N, deter)
  nn::Tensor stoch;  // (N, stoch * classes)
};

// Losses and posterior features of one observed batch.
struct WorldModelOutput {
  nn::Tensor loss;         // scalar: recon + dyn * KL_dyn + rep * KL_rep + cont (+ reward)
  nn::Tensor features;     // (T * B, feat) u_t = [h_t; s_t] of the posterior
  nn::Tensor post_probs;   // (T * B, stoch * classes) posterior probabilities
  nn::Tensor deter;        // (T * B, deter)
  nn::Tensor stoch;        // (T * B, stoch * classes) sampled one-hot posterior latents
  nn::Tensor cont_logits;  // (T * B, 1) the continuation head's logits on `features`
  float recon = 0, kl = 0, dyn = 0, rep = 0, cont = 0, reward = 0;  // loss terms (means)
};

// World model parameters and computations. Parameters: group "world_model" (encoder, RSSM,
// decoder, continuation head) and group "reward_head" (two-hot reward head, task phases).
class WorldModel {
 public:
  // Creates and initialises all parameters from `rng`.
  WorldModel(const WorldModelConfig& config, nn::Rng& rng);
  WorldModel(const WorldModel&) = delete;
  WorldModel& operator=(const WorldModel&) = delete;

  const WorldModelConfig& config() const { return config_; }
  nn::ParamGroup& params() { return params_; }
  // Whether acting (encode, obs_step, initial) uses a parameter of the "world_model" group:
  // the encoder's and the RSSM's do; the decoder's and the continuation head's do not.
  static bool acts_with(const std::string& param);
  nn::ParamGroup& reward_params() { return reward_params_; }

  // The learned initial state for n rows: h0 = tanh(w), s0 = the prior's mode at h0.
  RssmState initial(int n);
  // One prior step: h' = GRU(h, img_in([s, a])), s' ~ prior(h'). action is (N, 9) one-hot;
  // prior_probs, when given, receives the (N, stoch * classes) prior probabilities.
  RssmState img_step(const RssmState& prev, nn::Tensor action, nn::Rng& rng,
                     nn::Tensor* prior_probs = nullptr);
  // One posterior step from an embedding: h' as in the prior step, then s' ~ q(s | h', embed)
  // (the prior is not sampled). embed is (N, embed_dim); is_first is (N, 1) 0/1 and resets
  // state and action to the initial ones where 1. post_probs / prior_probs receive
  // (N, stoch * classes) when given (the prior's only then computed).
  RssmState obs_step(const RssmState& prev, nn::Tensor action, nn::Tensor embed,
                     nn::Tensor is_first, nn::Rng& rng, nn::Tensor* post_probs = nullptr,
                     nn::Tensor* prior_probs = nullptr);
  // Encodes RGB images: images is (N, image, image, 3) in [0, 1]; result (N, embed_dim).
  nn::Tensor encode(nn::Tensor images);
  // Decodes features (N, feat) into the mean image (N, image, image, 3) in about [0, 1].
  nn::Tensor decode(nn::Tensor features);
  // Continuation logits (N, 1) of features (N, feat).
  nn::Tensor cont_logits(nn::Tensor features);
  // Reward two-hot logits (N, 255) of features (N, feat); callers pass stop-gradient features.
  nn::Tensor reward_logits(nn::Tensor features);
  // The prior probabilities (N, stoch * classes) at deterministic states h (N, deter).
  nn::Tensor prior_probs(nn::Tensor deter);
  // u = [h; s]: (N, feat).
  static nn::Tensor features(const RssmState& state);

  // Runs the posterior over a batch and returns the loss and the posterior features. The
  // reward loss is added only when with_reward (task phases; the batch must carry rewards)
  // and is computed on stop-gradient features, so it never shapes the representation.
  WorldModelOutput observe(const SequenceBatch& batch, bool with_reward, nn::Rng& rng);

  // Converts a batch's frames to a time-major (T * B, H, W, 3) RGB tensor in [0, 1].
  static nn::Tensor batch_images(const SequenceBatch& batch);
  // The time-major row (step t of sequence b at t * batch + b) of a batch-major index of a
  // (B, T) field (step t of sequence b at b * length + t).
  static std::size_t time_major_row(std::size_t index, int batch, int length) {
    const auto b = static_cast<std::size_t>(batch), t = static_cast<std::size_t>(length);
    return (index % t) * b + index / t;
  }
  // A time-major (T * B, 1) column of a (B, T) field such as is_first.
  static nn::Tensor time_major_column(const std::vector<float>& field, int batch, int length);
  // Time-major (T * B, 9) one-hot of the actions taken at each step (actions is (B, T)).
  static nn::Tensor action_one_hot(const std::vector<int>& actions, int batch, int length);
  // A (N, 9) one-hot of one action per row.
  static nn::Tensor one_hot(const std::vector<int>& actions);

 private:
  WorldModelConfig config_;
  nn::ParamGroup params_{"world_model"};
  nn::ParamGroup reward_params_{"reward_head"};
  nn::ConvEncoder encoder_;
  nn::ConvDecoder decoder_;
  nn::Linear img_in_;
  nn::LayerNorm img_in_norm_;
  nn::GruCell gru_;
  nn::Mlp prior_head_;
  nn::Mlp post_head_;
  nn::Mlp cont_head_;
  nn::Mlp reward_head_;
  nn::Parameter* initial_ = nullptr;  // (1, deter), tanh gives h0

  // h' = GRU(h, img_in([s, a])), the deterministic part of a step.
  nn::Tensor next_deter(const RssmState& prev, nn::Tensor action);
};

}  // namespace indrive::agent
