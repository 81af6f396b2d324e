#include "indrive/agent/disagreement.h"

#include <algorithm>
#include <cmath>

#include "indrive/basics/check.h"
#include "intrinsic_math.h"

namespace indrive::agent {

using nn::Shape;
using nn::Tensor;
using namespace intrinsic_math;

LatentDisagreement::LatentDisagreement(const IntrinsicConfig& config, const WorldModelConfig& model,
                                       nn::Rng& rng)
    : IntrinsicModule(config), classes_(model.classes), units_(config.units), deter_(model.deter) {
  INDRIVE_CHECK(config.layers >= 1) << "the disagreement ensemble needs a hidden layer";
  for (int k = 0; k < config.ensemble; ++k) {
    members_.emplace_back(params_, "ld.member" + std::to_string(k), model.feat_dim() + kNumActions,
                          nn::MlpOptions{.units = config.units,
                                         .layers = config.layers,
                                         .out = model.stoch_dim(),
                                         .one_hot_from = model.deter},
                          rng);
  }
  make_optimizer();
}

Tensor LatentDisagreement::probabilities(Tensor logits) const {
  const std::int64_t n = logits.dim(0), s = logits.dim(1);
  Tensor probs = nn::softmax(nn::reshape(logits, Shape{n * s / classes_, classes_}));
  return nn::reshape(probs, Shape{n, s});
}

Tensor LatentDisagreement::predict(int k, Tensor input) {
  return probabilities(members_[k](input));
}

Tensor LatentDisagreement::stacked_first_weights() {
  std::vector<Tensor> weights;
  for (const nn::Mlp& member : members_) {
    INDRIVE_CHECK(!member.first_bias().defined()) << "ensemble members' first layers have no bias";
    weights.push_back(member.first_weight());
  }
  return nn::concat(weights, 1);
}

std::vector<Tensor> LatentDisagreement::all_logits(Tensor input, Tensor stacked) {
  // One (N, in) x (in, K * units) product instead of K products of (in, units): the GEMM is K
  // times wider, which suits the kernels better than K narrow ones (and is one call, not K).
  // The input is [deter, stoch, action]: the one-hot stoch and action pick rows of the weights.
  Tensor first = nn::linear_one_hot_tail(input, stacked, Tensor(), deter_);
  std::vector<Tensor> logits;
  logits.reserve(members_.size());
  for (int k = 0; k < members(); ++k) {
    logits.push_back(
        members_[k].after_first(nn::slice(first, static_cast<std::int64_t>(k) * units_,
                                          static_cast<std::int64_t>(k + 1) * units_, 1)));
  }
  return logits;
}

Tensor LatentDisagreement::loss(const Transitions& batch) {
  Tensor input = nn::concat({batch.feat, batch.action}, -1);
  const std::int64_t n = input.dim(0), s = batch.next_post.dim(1);
  Tensor target = nn::reshape(batch.next_post, Shape{n * s / classes_, classes_});
  Tensor total;
  const std::vector<Tensor> member_logits = all_logits(input, stacked_first_weights());
  for (int k = 0; k < members(); ++k) {
    const Tensor& logits = member_logits[k];
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
  const std::int64_t n = feat.dim(0);
  std::vector<float> out(n);
  const Tensor stacked = stacked_first_weights();  // in the caller's graph, read by every chunk
  // Rows are scored in chunks of a fixed size, each on one thread and its own graph, whose
  // activations are given back after the chunk: the K members' hidden layers and softmaxes over
  // all H * N imagined states would otherwise take over a gigabyte that is written once and
  // read once. Whole chunks in parallel use every thread through the members' many small ops,
  // which split op by op would mostly run on one; and the fixed size keeps the rewards the same
  // for any thread count.
  const std::int64_t chunks = (n + kRewardChunkRows - 1) / kRewardChunkRows;
  nn::parallel_tasks(chunks, [&](std::int64_t c) {
    const std::int64_t r0 = c * kRewardChunkRows, r1 = std::min(n, r0 + kRewardChunkRows);
    score_rows(nn::concat({nn::slice(feat, r0, r1, 0), nn::slice(action, r0, r1, 0)}, -1), stacked,
               out.data() + r0);
  });
  scale_raw(out, config_.disag_scale);
  return out;
}

void LatentDisagreement::score_rows(Tensor input, Tensor stacked, float* out) {
  const std::vector<Tensor> logits = all_logits(input, stacked);
  std::vector<Tensor> preds(members());
  for (int k = 0; k < members(); ++k) preds[k] = probabilities(logits[k]);
  const std::int64_t rows = input.dim(0), s = preds[0].dim(1);
  const float inv_k = 1.0f / static_cast<float>(members());
  std::vector<float> mean(s), var(s);
  for (std::int64_t i = 0; i < rows; ++i) {
    const std::int64_t row = i * s;
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
}

}  // namespace indrive::agent
