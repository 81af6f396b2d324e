#include "indrive/agent/rnd.h"

#include <algorithm>
#include <cmath>

#include "indrive/basics/check.h"
#include "intrinsic_math.h"

namespace indrive::agent {

using nn::Shape;
using nn::Tensor;
using namespace intrinsic_math;

Rnd::Rnd(const IntrinsicConfig& config, const WorldModelConfig& model, nn::Rng& rng)
    : IntrinsicModule(config),
      target_(target_params_, "rnd.target", model.feat_dim(),
              {.units = config.units,
               .layers = config.layers,
               .out = config.rnd_embed,
               .one_hot_from = model.deter},
              rng),
      predictor_(params_, "rnd.predictor", model.feat_dim(),
                 {.units = config.units,
                  .layers = config.layers,
                  .out = config.rnd_embed,
                  .one_hot_from = model.deter},
                 rng),
      norm_(config.norm_rate, config.norm_eps) {
  make_optimizer();
}

Tensor Rnd::loss(const Transitions& batch) {
  // The target is a constant function: its output gets no gradient.
  Tensor target = nn::stop_gradient(target_(batch.next_feat));
  Tensor error = nn::scale(row_sum(nn::squared_error(predictor_(batch.next_feat), target)),
                           1.0f / static_cast<float>(target.dim(1)));
  Tensor total = nn::mean(error);
  last_loss_ = total.item();
  return total;
}

std::vector<float> Rnd::reward(Tensor feat, Tensor action, Tensor next_feat) {
  (void)feat, (void)action;
  nn::NoGradGuard no_grad;
  Tensor target = target_(next_feat);
  std::vector<float> error =
      to_vector(nn::scale(row_sum(nn::squared_error(predictor_(next_feat), target)),
                          1.0f / static_cast<float>(target.dim(1))));
  scale_raw(error, config_.rnd_scale);
  norm_.update(error);
  norm_.normalize(error);
  return error;
}

}  // namespace indrive::agent
