// Latent ensemble disagreement (LD), the intrinsic reward of InDRiVE: K predictors of the next
// posterior's categorical probabilities from [u_t, onehot(a_t)]; the reward is disag_scale times
// the mean over latent dimensions of the variance across members (or its square root with
// intrinsic.disag_reward=std). See intrinsic.h for the interface the learner calls.
#pragma once

#include <vector>

#include "indrive/agent/intrinsic.h"

namespace indrive::agent {

// Latent ensemble disagreement (InDRiVE).
class LatentDisagreement : public IntrinsicModule {
 public:
  LatentDisagreement(const IntrinsicConfig& config, const WorldModelConfig& model, nn::Rng& rng);
  nn::Tensor loss(const Transitions& batch) override;
  std::vector<float> reward(nn::Tensor feat, nn::Tensor action, nn::Tensor next_feat) override;
  // Predicted next-latent probabilities of member k: input (N, feat + 9), result (N, S).
  nn::Tensor predict(int k, nn::Tensor input);
  // Every member's next-latent logits for one input (N, feat + 9), each (N, S): the members'
  // first products, which share the input, as one GEMM with their weights side by side
  // (`stacked`, from stacked_first_weights()), the rest member by member.
  std::vector<nn::Tensor> all_logits(nn::Tensor input, nn::Tensor stacked);
  // The members' first-layer weights side by side, (feat + 9, K * units).
  nn::Tensor stacked_first_weights();
  int members() const { return static_cast<int>(members_.size()); }
  // Imagined states scored per chunk by reward(); chunks run in parallel.
  static constexpr std::int64_t kRewardChunkRows = 512;

 private:
  // The raw reward of each row of `input` (rows, feat + 9) into out[0, rows): the mean over
  // latents of the members' variance (or standard deviation), before the scale.
  void score_rows(nn::Tensor input, nn::Tensor stacked, float* out);
  // Per latent group, the softmax of (N, S) logits.
  nn::Tensor probabilities(nn::Tensor logits) const;

  int classes_;
  int units_;
  int deter_;  // the input [deter, stoch, action] is one-hot from this column on
  std::vector<nn::Mlp> members_;
};

}  // namespace indrive::agent
