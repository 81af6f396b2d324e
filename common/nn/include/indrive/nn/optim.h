// Optimisers over parameter groups: Adam with global gradient-norm clipping and warm-up, and an
// exponential moving average (EMA) copy of a group (DreamerV3's slow critic).
#pragma once

#include <cstdint>
#include <span>
#include <string_view>
#include <vector>

#include "indrive/nn/tensor.h"

namespace indrive::nn {

// Adam settings. DreamerV3 v1: world model lr 1e-4, eps 1e-8, clip 1000; actor and critic
// lr 3e-5, eps 1e-5, clip 100.
struct AdamConfig {
  float lr = 1e-4f;
  float beta1 = 0.9f;
  float beta2 = 0.999f;
  float eps = 1e-8f;
  float clip = 1000.0f;       // global gradient-norm limit of the group; <= 0 disables clipping
  std::int64_t warmup = 0;    // steps of linear learning-rate warm-up from 0; 0 disables
  float weight_decay = 0.0f;  // decoupled (AdamW-style) decay; 0 disables
};

// What one optimiser step did.
struct StepStats {
  float grad_norm = 0;   // global L2 norm of the group's gradients before clipping
  float lr = 0;          // learning rate used (after warm-up)
  bool skipped = false;  // true when the gradient was not finite and no update was applied
};

// Adam over one parameter group. A non-finite gradient norm skips the update (counted, not a
// crash) and zeroes the gradients.
class Adam {
 public:
  // The group must outlive the optimiser and must not gain parameters afterwards. With a
  // `prefix`, only the group's parameters whose names start with it are optimised (one head of
  // a model, say); the others are never read or changed (checked: the prefix must match one).
  Adam(ParamGroup& group, AdamConfig config, std::string_view prefix = {});
  // Clips the gradients of its parameters to config.clip by global norm, applies one Adam
  // update, and zeroes those gradients.
  StepStats step();
  // Number of updates applied so far.
  std::int64_t steps() const { return steps_; }
  // Number of steps skipped because the gradient was not finite.
  std::int64_t skipped_steps() const { return skipped_; }
  const AdamConfig& config() const { return config_; }
  // Serializes the moments and the step counter (with the group's names and shapes).
  std::vector<std::uint8_t> save_state() const;
  // Restores a state from save_state(); throws SerializationError when it does not fit.
  void load_state(std::span<const std::uint8_t> blob);

 private:
  ParamGroup& group_;
  std::size_t group_size_;          // the group's parameter count when the optimiser was made
  std::vector<Parameter*> params_;  // the group's parameters it optimises
  AdamConfig config_;
  std::int64_t steps_ = 0;
  std::int64_t skipped_ = 0;
  std::vector<std::vector<float>> m_, v_;
};

// target <- (1 - rate) * target + rate * source, parameter by parameter. Both groups must have
// the same parameter names (after their group prefix) and shapes.
class Ema {
 public:
  // Checks that the groups match; throws SerializationError naming the first mismatch.
  Ema(const ParamGroup& source, ParamGroup& target, float rate = 0.02f);
  // Moves the target one step towards the source.
  void update();
  // Copies the source into the target exactly.
  void copy();

 private:
  const ParamGroup& source_;
  ParamGroup& target_;
  float rate_;
};

// Global L2 norm of the gradients of a group.
float grad_norm(const ParamGroup& group);

}  // namespace indrive::nn
