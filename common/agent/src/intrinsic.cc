#include "indrive/agent/intrinsic.h"

#include <algorithm>
#include <cmath>

#include "indrive/agent/disagreement.h"
#include "indrive/agent/icm.h"
#include "indrive/agent/rnd.h"
#include "indrive/basics/check.h"

namespace indrive::agent {

using nn::Shape;
using nn::Tensor;

Transitions make_transitions(Tensor features, Tensor post_probs, Tensor actions, Tensor is_first,
                             int batch) {
  const std::int64_t n = features.dim(0);
  INDRIVE_CHECK(n % batch == 0 && n > batch) << "need at least two time steps";
  Transitions out;
  Tensor feat = nn::stop_gradient(features);
  out.feat = nn::slice(feat, 0, n - batch, 0);
  out.next_feat = nn::slice(feat, batch, n, 0);
  out.next_post = nn::slice(nn::stop_gradient(post_probs), batch, n, 0);
  out.action = nn::slice(nn::stop_gradient(actions), 0, n - batch, 0);
  out.mask = nn::rsub_scalar(1.0f, nn::slice(nn::stop_gradient(is_first), batch, n, 0));
  return out;
}

IntrinsicModule::IntrinsicModule(const IntrinsicConfig& config) : config_(config) {}

void IntrinsicModule::scale_raw(std::vector<float>& raw, float scale) {
  double sum = 0.0, square_sum = 0.0;
  for (float& r : raw) {
    sum += r;
    square_sum += static_cast<double>(r) * r;
    r *= scale;
  }
  const double n = std::max<double>(1.0, static_cast<double>(raw.size()));
  last_raw_reward_ = static_cast<float>(sum / n);
  last_raw_std_ =
      static_cast<float>(std::sqrt(std::max(0.0, square_sum / n - (sum / n) * (sum / n))));
}

void IntrinsicModule::make_optimizer() {
  optimizer_ = std::make_unique<nn::Adam>(
      params_, nn::AdamConfig{.lr = config_.lr, .eps = config_.eps, .clip = config_.clip});
}

std::unique_ptr<IntrinsicModule> make_intrinsic(const IntrinsicConfig& config,
                                                const WorldModelConfig& model, nn::Rng& rng) {
  switch (config.method) {
    case Method::kDisag:
      return std::make_unique<LatentDisagreement>(config, model, rng);
    case Method::kIcm:
      return std::make_unique<Icm>(config, model, rng);
    case Method::kRnd:
      return std::make_unique<Rnd>(config, model, rng);
  }
  INDRIVE_CHECK(false) << "unknown intrinsic method";
  return nullptr;
}

}  // namespace indrive::agent
