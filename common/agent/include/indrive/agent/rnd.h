// Random network distillation (RND), a baseline of the paper: a fixed random target f(u) and a
// trained predictor p(u); the reward is Norm(rnd_scale * ||p - f||^2). See intrinsic.h.
#pragma once

#include <span>
#include <vector>

#include "indrive/agent/intrinsic.h"

namespace indrive::agent {

// Random network distillation.
class Rnd : public IntrinsicModule {
 public:
  Rnd(const IntrinsicConfig& config, const WorldModelConfig& model, nn::Rng& rng);
  nn::Tensor loss(const Transitions& batch) override;
  std::vector<float> reward(nn::Tensor feat, nn::Tensor action, nn::Tensor next_feat) override;
  std::vector<nn::ParamGroup*> groups() override { return {&params_, &target_params_}; }
  std::vector<float> normalizer_state() const override { return norm_.state(); }
  void set_normalizer_state(std::span<const float> s) override { norm_.set_state(s); }
  // The fixed target network's parameters (never trained).
  nn::ParamGroup& target_params() { return target_params_; }

 private:
  nn::ParamGroup target_params_{"rnd_target"};
  nn::Mlp target_;
  nn::Mlp predictor_;
  RunningNormalizer norm_;
};

}  // namespace indrive::agent
