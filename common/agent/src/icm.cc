#include "indrive/agent/icm.h"

#include <algorithm>
#include <cmath>

#include "indrive/basics/check.h"
#include "intrinsic_math.h"

namespace indrive::agent {

using nn::Shape;
using nn::Tensor;
using namespace intrinsic_math;

Icm::Icm(const IntrinsicConfig& config, const WorldModelConfig& model, nn::Rng& rng)
    : IntrinsicModule(config),
      inverse_(params_, "icm.inverse", 2 * model.feat_dim(),
               {.units = config.units, .layers = config.layers, .out = kNumActions}, rng),
      forward_(params_, "icm.forward", model.feat_dim() + kNumActions,
               {.units = config.units,
                .layers = config.layers,
                .out = model.feat_dim(),
                .one_hot_from = model.deter},
               rng),
      norm_(config.norm_rate, config.norm_eps) {
  make_optimizer();
}

Tensor Icm::loss(const Transitions& batch) {
  Tensor logits = inverse_(nn::concat({batch.feat, batch.next_feat}, -1));
  Tensor inverse = nn::scale(row_sum(nn::mul(batch.action, nn::log_softmax(logits))), -1.0f);
  Tensor pred = forward_(nn::concat({batch.feat, batch.action}, -1));
  Tensor forward = nn::scale(row_sum(nn::squared_error(pred, batch.next_feat)),
                             1.0f / static_cast<float>(pred.dim(1)));
  Tensor total = nn::add(nn::scale(masked_mean(inverse, batch.mask), config_.icm_inverse_scale),
                         masked_mean(forward, batch.mask));
  last_loss_ = total.item();
  return total;
}

std::vector<float> Icm::reward(Tensor feat, Tensor action, Tensor next_feat) {
  nn::NoGradGuard no_grad;
  Tensor pred = forward_(nn::concat({feat, action}, -1));
  std::vector<float> error = to_vector(nn::scale(row_sum(nn::squared_error(pred, next_feat)),
                                                 1.0f / static_cast<float>(pred.dim(1))));
  scale_raw(error, config_.icm_scale);
  norm_.update(error);
  norm_.normalize(error);
  for (float& r : error) r *= config_.icm_eta;
  return error;
}

}  // namespace indrive::agent
