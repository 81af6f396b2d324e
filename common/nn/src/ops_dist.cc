// Categorical distributions, two-hot regression and losses.
#include <algorithm>
#include <cmath>

#include "indrive/nn/ops.h"
#include "ops_internal.h"

namespace indrive::nn {

using detail::grad_of;
using detail::Node;

namespace {

// (..., G * classes) viewed as (rows * G, classes), the grouping of the categoricals.
Shape grouped(const Shape& s, int classes) {
  INDRIVE_CHECK(classes > 0 && s.cols() % classes == 0)
      << "last axis of " << s.str() << " is not a multiple of " << classes << " classes";
  return Shape{s.numel() / classes, classes};
}

// Identity gradient to in[0] (straight-through estimator).
void straight_through_backward(Node& n) {
  bool fresh = false;
  float* gp = detail::grad_for_write(n.in[0], &fresh);
  if (gp == nullptr) return;
  const float* gy = n.grad;
  const std::int64_t count = n.shape.numel();
  if (fresh)
    std::copy_n(gy, count, gp);
  else
    for (std::int64_t i = 0; i < count; ++i) gp[i] += gy[i];
}

}  // namespace

Tensor unimix_probs(Tensor logits, int classes, float mix) {
  Tensor probs = softmax(reshape(logits, grouped(logits.shape(), classes)));
  Tensor mixed = add_scalar(scale(probs, 1.0f - mix), mix / static_cast<float>(classes));
  return reshape(mixed, logits.shape());
}

Tensor sample_straight_through(Tensor probs, int classes, Rng& rng) {
  const Shape g = grouped(probs.shape(), classes);
  Graph& graph = current_graph();
  Node* n = graph.new_node(probs.shape());
  const float* p = probs.data();
  float* y = n->value;
  std::fill_n(y, probs.numel(), 0.0f);
  for (std::int64_t r = 0; r < g.dims[0]; ++r) {
    // Inverse-CDF sampling; the last class takes any rounding remainder.
    const float u = rng.uniform();
    const float* pr = p + r * classes;
    float acc = 0.0f;
    int pick = classes - 1;
    for (int c = 0; c < classes; ++c) {
      acc += pr[c];
      if (u < acc) {
        pick = c;
        break;
      }
    }
    y[r * classes + pick] = 1.0f;
  }
  // Value one_hot; gradient identity: equals one_hot + probs - stop_gradient(probs).
  graph.record(n, straight_through_backward, {probs.node()});
  return Tensor(n);
}

Tensor mode_one_hot(Tensor probs, int classes) {
  const Shape g = grouped(probs.shape(), classes);
  Tensor out = zeros(probs.shape());
  for (std::int64_t r = 0; r < g.dims[0]; ++r) {
    const float* pr = probs.data() + r * classes;
    int best = 0;
    for (int c = 1; c < classes; ++c)
      if (pr[c] > pr[best]) best = c;
    out.data()[r * classes + best] = 1.0f;
  }
  return out;
}

Tensor kl_categorical(Tensor p, Tensor q) {
  INDRIVE_CHECK(p.shape() == q.shape())
      << "KL of " << p.shape().str() << " and " << q.shape().str();
  return sum(mul(p, sub(log(p), log(q))), -1);
}

Tensor entropy(Tensor p) { return scale(sum(mul(p, log(p)), -1), -1.0f); }

namespace {

float bin_value(int k) {
  return kTwoHotLow + (kTwoHotHigh - kTwoHotLow) * static_cast<float>(k) / (kTwoHotBins - 1);
}

// The bin values as a (1, kTwoHotBins) tensor.
Tensor bins_row() {
  Tensor b = empty(Shape{1, kTwoHotBins});
  for (int k = 0; k < kTwoHotBins; ++k) b.data()[k] = bin_value(k);
  return b;
}

}  // namespace

Tensor twohot(Tensor target) {
  INDRIVE_CHECK_EQ(target.numel(), target.rows() * target.cols()) << "twohot target";
  const std::int64_t rows = target.numel();
  Tensor out = zeros(Shape{rows, kTwoHotBins});
  const float step = (kTwoHotHigh - kTwoHotLow) / (kTwoHotBins - 1);
  for (std::int64_t r = 0; r < rows; ++r) {
    const float t = target.data()[r];
    const float y = std::copysign(std::log1p(std::fabs(t)), t);
    float* row = out.data() + r * kTwoHotBins;
    if (y <= kTwoHotLow) {
      row[0] = 1.0f;
      continue;
    }
    if (y >= kTwoHotHigh) {
      row[kTwoHotBins - 1] = 1.0f;
      continue;
    }
    // Split the mass between the two neighbouring bins by distance.
    int below = static_cast<int>(std::floor((y - kTwoHotLow) / step));
    below = std::min(below, kTwoHotBins - 2);
    const float w_above = (y - bin_value(below)) / step;
    row[below] = 1.0f - w_above;
    row[below + 1] = w_above;
  }
  return out;
}

Tensor twohot_cross_entropy(Tensor logits, Tensor target) {
  INDRIVE_CHECK_EQ(logits.cols(), kTwoHotBins) << "two-hot logits " << logits.shape().str();
  INDRIVE_CHECK_EQ(logits.rows(), target.numel()) << "two-hot target " << target.shape().str();
  Tensor logp = log_softmax(reshape(logits, Shape{logits.rows(), kTwoHotBins}));
  return scale(sum(mul(logp, twohot(target)), -1), -1.0f);
}

Tensor twohot_mean(Tensor logits) {
  INDRIVE_CHECK_EQ(logits.cols(), kTwoHotBins) << "two-hot logits " << logits.shape().str();
  Tensor probs = softmax(reshape(logits, Shape{logits.rows(), kTwoHotBins}));
  return symexp(sum(mul(probs, bins_row()), -1));
}

namespace {

// in[0] logits, in[1] targets (no gradient).
void bce_backward(Node& n) {
  bool fresh = false;
  float* gx = detail::grad_for_write(n.in[0], &fresh);
  if (gx == nullptr) return;
  const float* x = n.in[0]->value;
  const float* t = n.in[1]->value;
  for (std::int64_t i = 0, e = n.shape.numel(); i < e; ++i) {
    const float g = n.grad[i] * (1.0f / (1.0f + std::exp(-x[i])) - t[i]);
    gx[i] = fresh ? g : gx[i] + g;
  }
}

void squared_error_backward(Node& n) {
  bool fresh = false;
  float* gx = detail::grad_for_write(n.in[0], &fresh);
  if (gx == nullptr) return;
  const float* x = n.in[0]->value;
  const float* t = n.in[1]->value;
  detail::parallel_for(n.shape.numel(), [&](std::int64_t s, std::int64_t e) {
    if (fresh)
      for (std::int64_t i = s; i < e; ++i) gx[i] = 2.0f * n.grad[i] * (x[i] - t[i]);
    else
      for (std::int64_t i = s; i < e; ++i) gx[i] += 2.0f * n.grad[i] * (x[i] - t[i]);
  });
}

}  // namespace

Tensor bce_with_logits(Tensor logits, Tensor target) {
  INDRIVE_CHECK(logits.shape() == target.shape())
      << "BCE of " << logits.shape().str() << " and " << target.shape().str();
  Graph& g = current_graph();
  Node* n = g.new_node(logits.shape());
  const float* x = logits.data();
  const float* t = target.data();
  for (std::int64_t i = 0, e = logits.numel(); i < e; ++i)
    n->value[i] = std::max(x[i], 0.0f) - x[i] * t[i] + std::log1p(std::exp(-std::fabs(x[i])));
  g.record(n, bce_backward, {logits.node(), nullptr});
  n->in[1] = target.node();
  return Tensor(n);
}

Tensor squared_error(Tensor pred, Tensor target) {
  INDRIVE_CHECK(pred.shape() == target.shape())
      << "squared error of " << pred.shape().str() << " and " << target.shape().str();
  Graph& g = current_graph();
  Node* n = g.new_node(pred.shape());
  const float* x = pred.data();
  const float* t = target.data();
  detail::parallel_for(pred.numel(), [&](std::int64_t s, std::int64_t e) {
    for (std::int64_t i = s; i < e; ++i) n->value[i] = (x[i] - t[i]) * (x[i] - t[i]);
  });
  g.record(n, squared_error_backward, {pred.node(), nullptr});
  n->in[1] = target.node();
  return Tensor(n);
}

Tensor mse(Tensor pred, Tensor target) { return mean(squared_error(pred, target)); }

}  // namespace indrive::nn
