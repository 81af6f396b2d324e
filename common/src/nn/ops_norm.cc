// LayerNorm, softmax and log-softmax over the last axis.
#include <cmath>

#include "indrive/common/nn/ops.h"
#include "ops_internal.h"

namespace indrive::nn {

using detail::grad_of;
using detail::Node;

namespace {

// Inputs: x (R, C), gamma (C) or null, beta (C) or null. saved: mean[R], rstd[R].
void layer_norm_backward(Node& n) {
  Node* x = n.in[0];
  Node* gamma = n.in[1];
  Node* beta = n.in[2];
  const std::int64_t rows = n.shape.rows(), cols = n.shape.cols();
  const float* mean = n.saved;
  const float* rstd = n.saved + rows;
  float* gx = grad_of(x);
  float* gg = grad_of(gamma);
  float* gb = grad_of(beta);
  const float* gam = gamma ? gamma->value : nullptr;
  const float inv_c = 1.0f / static_cast<float>(cols);
  for (std::int64_t r = 0; r < rows; ++r) {
    const float* xr = x->value + r * cols;
    const float* gy = n.grad + r * cols;
    const float mu = mean[r], rs = rstd[r];
    // dxhat = gy * gamma; dx = rstd * (dxhat - mean(dxhat) - xhat * mean(dxhat * xhat)).
    float sum_d = 0.0f, sum_dx = 0.0f;
    for (std::int64_t c = 0; c < cols; ++c) {
      const float xhat = (xr[c] - mu) * rs;
      const float d = gam ? gy[c] * gam[c] : gy[c];
      sum_d += d;
      sum_dx += d * xhat;
      if (gg) gg[c] += gy[c] * xhat;
      if (gb) gb[c] += gy[c];
    }
    if (gx) {
      float* gxr = gx + r * cols;
      const float md = sum_d * inv_c, mdx = sum_dx * inv_c;
      for (std::int64_t c = 0; c < cols; ++c) {
        const float xhat = (xr[c] - mu) * rs;
        const float d = gam ? gy[c] * gam[c] : gy[c];
        gxr[c] += rs * (d - md - xhat * mdx);
      }
    }
  }
}

}  // namespace

Tensor layer_norm(Tensor x, Tensor gamma, Tensor beta, float eps) {
  const std::int64_t rows = x.rows(), cols = x.cols();
  if (gamma.defined()) INDRIVE_CHECK_EQ(gamma.numel(), cols) << "LayerNorm scale";
  if (beta.defined()) INDRIVE_CHECK_EQ(beta.numel(), cols) << "LayerNorm offset";
  Graph& g = current_graph();
  Node* n = g.new_node(x.shape());
  n->saved = g.alloc(2 * rows);
  float* mean = n->saved;
  float* rstd = n->saved + rows;
  const float* gam = gamma.defined() ? gamma.data() : nullptr;
  const float* bet = beta.defined() ? beta.data() : nullptr;
  const float* xv = x.data();
  float* y = n->value;
  const float inv_c = 1.0f / static_cast<float>(cols);
  detail::parallel_for(rows * cols, [&](std::int64_t s, std::int64_t e) {
    // Rows whose first element falls in [s, e): chunking by elements keeps the split fixed.
    const std::int64_t r0 = (s + cols - 1) / cols, r1 = (e + cols - 1) / cols;
    for (std::int64_t r = r0; r < r1; ++r) {
      const float* xr = xv + r * cols;
      float* yr = y + r * cols;
      float mu = 0.0f;
      for (std::int64_t c = 0; c < cols; ++c) mu += xr[c];
      mu *= inv_c;
      float var = 0.0f;
      for (std::int64_t c = 0; c < cols; ++c) var += (xr[c] - mu) * (xr[c] - mu);
      var *= inv_c;
      const float rs = 1.0f / std::sqrt(var + eps);
      mean[r] = mu;
      rstd[r] = rs;
      for (std::int64_t c = 0; c < cols; ++c) {
        float v = (xr[c] - mu) * rs;
        if (gam) v *= gam[c];
        if (bet) v += bet[c];
        yr[c] = v;
      }
    }
  });
  g.record(
      n, layer_norm_backward,
      {x.node(), gamma.defined() ? gamma.node() : nullptr, beta.defined() ? beta.node() : nullptr});
  return Tensor(n);
}

namespace {

void softmax_backward(Node& n) {
  float* gx = grad_of(n.in[0]);
  if (gx == nullptr) return;
  const std::int64_t rows = n.shape.rows(), cols = n.shape.cols();
  for (std::int64_t r = 0; r < rows; ++r) {
    const float* y = n.value + r * cols;
    const float* gy = n.grad + r * cols;
    float dot = 0.0f;
    for (std::int64_t c = 0; c < cols; ++c) dot += gy[c] * y[c];
    float* g = gx + r * cols;
    for (std::int64_t c = 0; c < cols; ++c) g[c] += y[c] * (gy[c] - dot);
  }
}

void log_softmax_backward(Node& n) {
  float* gx = grad_of(n.in[0]);
  if (gx == nullptr) return;
  const std::int64_t rows = n.shape.rows(), cols = n.shape.cols();
  for (std::int64_t r = 0; r < rows; ++r) {
    const float* y = n.value + r * cols;
    const float* gy = n.grad + r * cols;
    float total = 0.0f;
    for (std::int64_t c = 0; c < cols; ++c) total += gy[c];
    float* g = gx + r * cols;
    for (std::int64_t c = 0; c < cols; ++c) g[c] += gy[c] - std::exp(y[c]) * total;
  }
}

// Writes softmax (or log-softmax) of each row of x into y.
void softmax_rows(const float* x, float* y, std::int64_t rows, std::int64_t cols, bool log) {
  detail::parallel_for(rows * cols, [&](std::int64_t s, std::int64_t e) {
    const std::int64_t r0 = (s + cols - 1) / cols, r1 = (e + cols - 1) / cols;
    for (std::int64_t r = r0; r < r1; ++r) {
      const float* xr = x + r * cols;
      float* yr = y + r * cols;
      float mx = xr[0];
      for (std::int64_t c = 1; c < cols; ++c) mx = std::max(mx, xr[c]);
      auto in = detail::ConstArray(xr, cols);
      auto out = detail::Array(yr, cols);
      out = (in - mx).exp();
      const float total = out.sum();
      if (log)
        out = in - (mx + std::log(total));
      else
        out *= 1.0f / total;
    }
  });
}

}  // namespace

Tensor softmax(Tensor x) {
  Graph& g = current_graph();
  Node* n = g.new_node(x.shape());
  softmax_rows(x.data(), n->value, x.rows(), x.cols(), false);
  g.record(n, softmax_backward, {x.node()});
  return Tensor(n);
}

Tensor log_softmax(Tensor x) {
  Graph& g = current_graph();
  Node* n = g.new_node(x.shape());
  softmax_rows(x.data(), n->value, x.rows(), x.cols(), true);
  g.record(n, log_softmax_backward, {x.node()});
  return Tensor(n);
}

}  // namespace indrive::nn
