// LayerNorm, softmax and log-softmax over the last axis.
#include <cmath>
#include <type_traits>
#include <vector>

#include "indrive/nn/ops.h"
#include "ops_internal.h"

namespace indrive::nn {

using detail::grad_of;
using detail::Node;

namespace {

// Rows per chunk of the LayerNorm loops: fixed, so the parallel split (and the order in which
// the per-chunk scale/offset gradients are summed) does not depend on the thread count.
constexpr std::int64_t kNormChunkRows = 512;

// Calls fn(std::integral_constant<int, W>{}) with W the first of `Widths` equal to cols, else
// with W = Eigen::Dynamic: rows of a common width get a kernel of fixed size, so that Eigen
// vectorises even rows shorter than one vector (a dynamic row that short stays scalar).
template <int... Widths, typename Fn>
void with_row_width(std::int64_t cols, Fn&& fn) {
  const bool fixed =
      ((cols == Widths ? (fn(std::integral_constant<int, Widths>{}), true) : false) || ...);
  if (!fixed) fn(std::integral_constant<int, Eigen::Dynamic>{});
}

// Calls fn(row_begin, row_end, chunk) over chunks of rows, in parallel when large.
template <typename Fn>
void for_row_chunks(std::int64_t rows, std::int64_t cols, Fn&& fn) {
  const std::int64_t chunks = (rows + kNormChunkRows - 1) / kNormChunkRows;
  const bool parallel = rows * cols >= detail::kParallelMin && chunks > 1 &&
                        omp_get_max_threads() > 1 && !omp_in_parallel();
#pragma omp parallel for schedule(dynamic, 1) if (parallel)
  for (std::int64_t c = 0; c < chunks; ++c)
    fn(c * kNormChunkRows, std::min(rows, (c + 1) * kNormChunkRows), c);
}

// The per-row part of LayerNorm's backward rule over rows [r0, r1): xh and g hold the chunk's
// normalised inputs and the gradient w.r.t. the norm's output (row r at (r - r0) * cols).
// dxhat = g * gamma; dx = rstd * (dxhat - mean(dxhat) - xhat * mean(dxhat * xhat)); the scale
// and offset gradients add into pg and pb. C is a compile-time width (the convolutions' 8-32
// channels per pixel, where a dynamic row's per-row overhead dominated: 0.64 ms for 32768 rows
// of 8) or Eigen::Dynamic.
template <int C>
void layer_norm_backward_rows(const float* xh_chunk, const float* g_chunk, const float* rstd,
                              const float* gam, float* pg, float* pb, float* gx, bool fresh,
                              std::int64_t r0, std::int64_t r1, std::int64_t cols) {
  using Row = Eigen::Array<float, C, 1>;
  using In = Eigen::Map<const Row>;
  using Out = Eigen::Map<Row>;
  const float inv_c = 1.0f / static_cast<float>(cols);
  for (std::int64_t r = r0; r < r1; ++r) {
    const In xh(xh_chunk + (r - r0) * cols, cols), g(g_chunk + (r - r0) * cols, cols);
    const float rs = rstd[r];
    // The row sums are vector reductions, as in the forward pass.
    float sum_d, sum_dx;
    if (gam) {
      const In gama(gam, cols);
      sum_d = (g * gama).sum();
      sum_dx = (g * gama * xh).sum();
    } else {
      sum_d = g.sum();
      sum_dx = (g * xh).sum();
    }
    if (pg) {
      Out(pg, cols) += g * xh;
      Out(pb, cols) += g;
    }
    if (gx) {
      Out gxr(gx + r * cols, cols);
      const float md = sum_d * inv_c, mdx = sum_dx * inv_c;
      if (gam) {
        const In gama(gam, cols);
        if (fresh)
          gxr = rs * (g * gama - md - xh * mdx);
        else
          gxr += rs * (g * gama - md - xh * mdx);
      } else {
        if (fresh)
          gxr = rs * (g - md - xh * mdx);
        else
          gxr += rs * (g - md - xh * mdx);
      }
    }
  }
}

// Shared by layer_norm and layer_norm_silu. Inputs: x (R, C), gamma (C) or null, beta (C) or
// null. saved: mean[R], rstd[R]. iparam[0]: 1 when SiLU follows the norm.
void layer_norm_backward(Node& n) {
  Node* x = n.in[0];
  Node* gamma = n.in[1];
  Node* beta = n.in[2];
  const bool with_silu = n.iparam[0] != 0;
  const std::int64_t rows = n.shape.rows(), cols = n.shape.cols();
  const float* mean = n.saved;
  const float* rstd = n.saved + rows;
  bool fresh = false;
  float* gx = detail::grad_for_write(x, &fresh);
  float* gg = grad_of(gamma);
  float* gb = grad_of(beta);
  const float* gam = gamma ? gamma->value : nullptr;
  const float* bet = beta ? beta->value : nullptr;
  const std::int64_t chunks = (rows + kNormChunkRows - 1) / kNormChunkRows;
  // Per-chunk partial sums of the scale and offset gradients, reduced in chunk order below.
  float* partial = (gg || gb) ? current_graph().alloc_zeroed(chunks * 2 * cols) : nullptr;
  for_row_chunks(rows, cols, [&](std::int64_t r0, std::int64_t r1, std::int64_t chunk) {
    float* pg = partial ? partial + chunk * 2 * cols : nullptr;
    float* pb = partial ? pg + cols : nullptr;
    // Chunk buffers: normalised x and the gradient w.r.t. the norm's output, computed for the
    // whole chunk at once so that the SiLU derivative runs vectorised.
    const std::int64_t count = (r1 - r0) * cols;
    thread_local std::vector<float> buffers;
    if (buffers.size() < static_cast<std::size_t>(3 * count)) buffers.resize(3 * count);
    float* xh_chunk = buffers.data();
    float* g_chunk = xh_chunk + count;
    float* s_chunk = g_chunk + count;
    for (std::int64_t r = r0; r < r1; ++r) {
      const float* xr = x->value + r * cols;
      float* xh = xh_chunk + (r - r0) * cols;
      const float mu = mean[r], rs = rstd[r];
      for (std::int64_t c = 0; c < cols; ++c) xh[c] = (xr[c] - mu) * rs;
    }
    const float* gy_chunk = n.grad + r0 * cols;
    if (with_silu) {
      // Recompute the norm's output v, then g = gy * d silu(v) / dv = gy s (1 + v (1 - s)).
      for (std::int64_t i = 0; i < count; i += cols)
        for (std::int64_t c = 0; c < cols; ++c) {
          float v = xh_chunk[i + c];
          if (gam) v *= gam[c];
          if (bet) v += bet[c];
          g_chunk[i + c] = v;
        }
      // The logistic is evaluated once into its own buffer: written inline in the expression
      // it would be computed twice per element (Eigen does not share subexpressions).
      detail::Array v(g_chunk, count), sig(s_chunk, count);
      const detail::ConstArray gy(gy_chunk, count);
      sig = v.logistic();
      v = gy * sig * (1.0f + v * (1.0f - sig));
    } else {
      std::copy_n(gy_chunk, count, g_chunk);
    }
    with_row_width<8, 16, 32>(cols, [&](auto width) {
      layer_norm_backward_rows<decltype(width)::value>(xh_chunk, g_chunk, rstd, gam, pg, pb, gx,
                                                       fresh, r0, r1, cols);
    });
  });
  if (partial) {
    for (std::int64_t chunk = 0; chunk < chunks; ++chunk) {
      const float* pg = partial + chunk * 2 * cols;
      if (gg)
        for (std::int64_t c = 0; c < cols; ++c) gg[c] += pg[c];
      if (gb)
        for (std::int64_t c = 0; c < cols; ++c) gb[c] += pg[cols + c];
    }
  }
}

// Normalises rows [r0, r1) of x (R, C) into y, saving each row's mean and 1 / std, then scale
// and offset (either may be null). C is a compile-time width or Eigen::Dynamic. The row sums
// run as Eigen reductions, which keep several vector accumulators: a plain float loop is one
// serial chain of adds (the compiler may not reorder them), and made this op 10% of a tiny
// agent update.
template <int C>
void normalize_rows(const float* xv, float* y, float* mean, float* rstd, const float* gam,
                    const float* bet, std::int64_t r0, std::int64_t r1, std::int64_t cols,
                    float eps) {
  using Row = Eigen::Array<float, C, 1>;
  using In = Eigen::Map<const Row>;
  using Out = Eigen::Map<Row>;
  const float inv_c = 1.0f / static_cast<float>(cols);
  for (std::int64_t r = r0; r < r1; ++r) {
    const In in(xv + r * cols, cols);
    Out out(y + r * cols, cols);
    const float mu = in.sum() * inv_c;
    const float var = (in - mu).square().sum() * inv_c;
    const float rs = 1.0f / std::sqrt(var + eps);
    mean[r] = mu;
    rstd[r] = rs;
    if (gam && bet)
      out = (in - mu) * rs * In(gam, cols) + In(bet, cols);
    else if (gam)
      out = (in - mu) * rs * In(gam, cols);
    else if (bet)
      out = (in - mu) * rs + In(bet, cols);
    else
      out = (in - mu) * rs;
  }
}

Tensor layer_norm_impl(Tensor x, Tensor gamma, Tensor beta, float eps, bool with_silu) {
  const std::int64_t rows = x.rows(), cols = x.cols();
  if (gamma.defined()) {
    INDRIVE_CHECK_EQ(gamma.numel(), cols) << "LayerNorm scale";
  }
  if (beta.defined()) {
    INDRIVE_CHECK_EQ(beta.numel(), cols) << "LayerNorm offset";
  }
  Graph& g = current_graph();
  Node* n = g.new_node(x.shape());
  n->saved = g.alloc(2 * rows);
  n->iparam[0] = with_silu ? 1 : 0;
  float* mean = n->saved;
  float* rstd = n->saved + rows;
  const float* gam = gamma.defined() ? gamma.data() : nullptr;
  const float* bet = beta.defined() ? beta.data() : nullptr;
  const float* xv = x.data();
  float* y = n->value;
  for_row_chunks(rows, cols, [&](std::int64_t r0, std::int64_t r1, std::int64_t) {
    // The convolutions' 8-32 channels per pixel get fixed-size kernels.
    with_row_width<8, 16, 32>(cols, [&](auto width) {
      normalize_rows<decltype(width)::value>(xv, y, mean, rstd, gam, bet, r0, r1, cols, eps);
    });
    // SiLU over the whole chunk at once: per row it would be scalar wherever a row is shorter
    // than a vector (the encoder's and decoder's 8-32 channels per pixel).
    if (with_silu) {
      auto out = detail::Array(y + r0 * cols, (r1 - r0) * cols);
      out = out * out.logistic();
    }
  });
  g.record(
      n, layer_norm_backward,
      {x.node(), gamma.defined() ? gamma.node() : nullptr, beta.defined() ? beta.node() : nullptr});
  return Tensor(n);
}

}  // namespace

Tensor layer_norm(Tensor x, Tensor gamma, Tensor beta, float eps) {
  return layer_norm_impl(x, gamma, beta, eps, false);
}

Tensor layer_norm_silu(Tensor x, Tensor gamma, Tensor beta, float eps) {
  return layer_norm_impl(x, gamma, beta, eps, true);
}

namespace {

// Calls fn(r0, r1) over row ranges that together cover [0, rows); the ranges are whole rows of
// the fixed element chunks of parallel_for, so they do not depend on the thread count.
template <typename Fn>
void for_rows(std::int64_t rows, std::int64_t cols, Fn&& fn) {
  detail::parallel_for(rows * cols, [&](std::int64_t s, std::int64_t e) {
    const std::int64_t r0 = (s + cols - 1) / cols, r1 = (e + cols - 1) / cols;
    if (r0 < r1) fn(r0, r1);
  });
}

// The backward rules run per row like the forward ones, with fixed-size kernels for the
// latents' 16 and 32 classes, so that the exponentials of log-softmax's rule are vector code
// rather than one std::exp per element (that rule was 9% of a tiny update's backward pass).
template <int C>
void softmax_backward_rows(const float* y, const float* gy, float* gx, std::int64_t r0,
                           std::int64_t r1, std::int64_t cols, bool log, bool fresh) {
  using Row = Eigen::Array<float, C, 1>;
  for (std::int64_t r = r0; r < r1; ++r) {
    const Eigen::Map<const Row> yr(y + r * cols, cols), gyr(gy + r * cols, cols);
    Eigen::Map<Row> g(gx + r * cols, cols);
    if (log) {
      // y = log p: dx = gy - p * sum(gy).
      const float total = gyr.sum();
      if (fresh)
        g = gyr - yr.exp() * total;
      else
        g += gyr - yr.exp() * total;
    } else {
      // y = p: dx = p * (gy - sum(gy * p)).
      const float dot = (gyr * yr).sum();
      if (fresh)
        g = yr * (gyr - dot);
      else
        g += yr * (gyr - dot);
    }
  }
}

void softmax_backward_impl(Node& n, bool log) {
  bool fresh = false;
  float* gx = detail::grad_for_write(n.in[0], &fresh);
  if (gx == nullptr) return;
  const std::int64_t rows = n.shape.rows(), cols = n.shape.cols();
  for_rows(rows, cols, [&](std::int64_t r0, std::int64_t r1) {
    with_row_width<16, 32>(cols, [&](auto width) {
      softmax_backward_rows<decltype(width)::value>(n.value, n.grad, gx, r0, r1, cols, log, fresh);
    });
  });
}

void softmax_backward(Node& n) { softmax_backward_impl(n, false); }

void log_softmax_backward(Node& n) { softmax_backward_impl(n, true); }

// Writes softmax (or log-softmax) of each row of x into y.
// Softmax (or log-softmax) of rows [r0, r1); C is a compile-time width or Eigen::Dynamic, as
// in LayerNorm.
template <int C>
void softmax_row_range(const float* x, float* y, std::int64_t r0, std::int64_t r1,
                       std::int64_t cols, bool log) {
  using Row = Eigen::Array<float, C, 1>;
  for (std::int64_t r = r0; r < r1; ++r) {
    const Eigen::Map<const Row> in(x + r * cols, cols);
    Eigen::Map<Row> out(y + r * cols, cols);
    const float mx = in.maxCoeff();  // a vector reduction, as in LayerNorm
    out = (in - mx).exp();
    const float total = out.sum();
    if (log)
      out = in - (mx + std::log(total));
    else
      out *= 1.0f / total;
  }
}

void softmax_rows(const float* x, float* y, std::int64_t rows, std::int64_t cols, bool log) {
  for_rows(rows, cols, [&](std::int64_t r0, std::int64_t r1) {
    // The latents' 16 and 32 classes get fixed-size kernels (one or two vectors per row).
    with_row_width<16, 32>(cols, [&](auto width) {
      softmax_row_range<decltype(width)::value>(x, y, r0, r1, cols, log);
    });
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
