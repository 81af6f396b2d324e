#include "indrive/common/agent/intrinsic.h"

#include <algorithm>
#include <cmath>

#include "indrive/common/check.h"

namespace indrive::agent {

using nn::Shape;
using nn::Tensor;

namespace {

// Mean over rows of mask * per_row, divided by the number of valid rows. per_row is (N, 1).
Tensor masked_mean(Tensor per_row, Tensor mask) {
  float valid = 0;
  for (float m : mask.values()) valid += m;
  return nn::scale(nn::sum(nn::mul(per_row, mask)), 1.0f / std::max(1.0f, valid));
}

// Row sums of a (N, C) tensor as (N, 1).
Tensor row_sum(Tensor x) { return nn::reshape(nn::sum(x, -1), Shape{x.dim(0), 1}); }

std::vector<float> to_vector(Tensor x) { return {x.values().begin(), x.values().end()}; }

}  // namespace

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

// ---- LD ----

LatentDisagreement::LatentDisagreement(const IntrinsicConfig& config, const WorldModelConfig& model,
                                       nn::Rng& rng)
    : IntrinsicModule(config), classes_(model.classes) {
  for (int k = 0; k < config.ensemble; ++k) {
    members_.emplace_back(
        params_, "ld.member" + std::to_string(k), model.feat_dim() + kNumActions,
        nn::MlpOptions{.units = config.units, .layers = config.layers, .out = model.stoch_dim()},
        rng);
  }
  make_optimizer();
}

Tensor LatentDisagreement::predict(int k, Tensor input) {
  Tensor logits = members_[k](input);
  const std::int64_t n = logits.dim(0), s = logits.dim(1);
  Tensor probs = nn::softmax(nn::reshape(logits, Shape{n * s / classes_, classes_}));
  return nn::reshape(probs, Shape{n, s});
}

Tensor LatentDisagreement::loss(const Transitions& batch) {
  Tensor input = nn::concat({batch.feat, batch.action}, -1);
  const std::int64_t n = input.dim(0), s = batch.next_post.dim(1);
  Tensor target = nn::reshape(batch.next_post, Shape{n * s / classes_, classes_});
  Tensor total;
  for (int k = 0; k < members(); ++k) {
    Tensor logits = members_[k](input);
    Tensor logp = nn::log_softmax(nn::reshape(logits, Shape{n * s / classes_, classes_}));
    // Cross-entropy to the next posterior, summed over the latent groups.
    Tensor ce = nn::scale(row_sum(nn::reshape(nn::mul(target, logp), Shape{n, s})), -1.0f);
    Tensor member_loss = masked_mean(ce, batch.mask);
    total = total.defined() ? nn::add(total, member_loss) : member_loss;
  }
  last_loss_ = total.item() / members();
  return total;
}

std::vector<float> LatentDisagreement::reward(Tensor feat, Tensor action, Tensor next_feat) {
  (void)next_feat;
  nn::NoGradGuard no_grad;
  nn::Graph& graph = nn::current_graph();
  const std::int64_t n = feat.dim(0);
  // Rows are scored in chunks whose activations are given back to the arena after each chunk:
  // the K members' hidden layers and softmaxes over all H * N imagined states would otherwise
  // take over a gigabyte that is written once and read once.
  constexpr std::int64_t kChunkRows = 1024;
  std::vector<float> out(n);
  std::vector<float> mean, var;
  const float inv_k = 1.0f / static_cast<float>(members());
  std::vector<Tensor> preds(members());
  for (std::int64_t r0 = 0; r0 < n; r0 += kChunkRows) {
    const std::int64_t r1 = std::min(n, r0 + kChunkRows);
    const nn::Graph::Mark mark = graph.mark();
    Tensor input = nn::concat({nn::slice(feat, r0, r1, 0), nn::slice(action, r0, r1, 0)}, -1);
    for (int k = 0; k < members(); ++k) preds[k] = predict(k, input);
    const std::int64_t s = preds[0].dim(1);
    mean.resize(s);
    var.resize(s);
    for (std::int64_t i = r0; i < r1; ++i) {
      const std::int64_t row = (i - r0) * s;
      // Per latent d: mean and population variance across the members, summed in member order.
      std::fill(mean.begin(), mean.end(), 0.0f);
      for (const Tensor& p : preds) {
        const float* pr = p.data() + row;
        for (std::int64_t d = 0; d < s; ++d) mean[d] += pr[d];
      }
      for (std::int64_t d = 0; d < s; ++d) mean[d] *= inv_k;
      std::fill(var.begin(), var.end(), 0.0f);
      for (const Tensor& p : preds) {
        const float* pr = p.data() + row;
        for (std::int64_t d = 0; d < s; ++d) {
          const float diff = pr[d] - mean[d];
          var[d] += diff * diff;
        }
      }
      double total = 0.0;
      for (std::int64_t d = 0; d < s; ++d) {
        const float v = var[d] * inv_k;
        total += config_.disag_reward == DisagReward::kVariance ? v : std::sqrt(v);
      }
      out[i] = static_cast<float>(total / s);
    }
    for (Tensor& p : preds) p = Tensor();
    graph.rewind(mark);
  }
  scale_raw(out, config_.disag_scale);
  return out;
}

// ---- ICM ----

Icm::Icm(const IntrinsicConfig& config, const WorldModelConfig& model, nn::Rng& rng)
    : IntrinsicModule(config),
      inverse_(params_, "icm.inverse", 2 * model.feat_dim(),
               {.units = config.units, .layers = config.layers, .out = kNumActions}, rng),
      forward_(params_, "icm.forward", model.feat_dim() + kNumActions,
               {.units = config.units, .layers = config.layers, .out = model.feat_dim()}, rng),
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

// ---- RND ----

Rnd::Rnd(const IntrinsicConfig& config, const WorldModelConfig& model, nn::Rng& rng)
    : IntrinsicModule(config),
      target_(target_params_, "rnd.target", model.feat_dim(),
              {.units = config.units, .layers = config.layers, .out = config.rnd_embed}, rng),
      predictor_(params_, "rnd.predictor", model.feat_dim(),
                 {.units = config.units, .layers = config.layers, .out = config.rnd_embed}, rng),
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
