// Intrinsic curiosity module (ICM), a baseline of the paper: an inverse model
// CE(a_hat(u_t, u_{t+1}), a_t) and a forward model ||u_hat_{t+1} - u_{t+1}||^2; the reward is
// eta * Norm(icm_scale * forward error). See intrinsic.h for the interface.
#pragma once

#include <span>
#include <vector>

#include "indrive/agent/intrinsic.h"

namespace indrive::agent {

// Intrinsic curiosity module.
class Icm : public IntrinsicModule {
 public:
  Icm(const IntrinsicConfig& config, const WorldModelConfig& model, nn::Rng& rng);
  nn::Tensor loss(const Transitions& batch) override;
  std::vector<float> reward(nn::Tensor feat, nn::Tensor action, nn::Tensor next_feat) override;
  std::vector<float> normalizer_state() const override { return norm_.state(); }
  void set_normalizer_state(std::span<const float> s) override { norm_.set_state(s); }

 private:
  nn::Mlp inverse_;
  nn::Mlp forward_;
  RunningNormalizer norm_;
};

}  // namespace indrive::agent
