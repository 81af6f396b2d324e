// Matrix product and the fused linear layer (x * w + b) on the kernel layer's products, and the
// linear layer whose input ends in one-hot columns (gathered rows instead of a product).
#include <algorithm>
#include <limits>
#include <vector>

#if defined(__x86_64__)
#include <immintrin.h>
#endif

#include "indrive/nn/ops.h"
#include "ops_internal.h"

namespace indrive::nn {

using detail::cmat;
using detail::GemmOperand;
using detail::grad_of;
using detail::held;
using detail::mat;
using detail::Node;
using detail::operand;

namespace {

// Inputs: x (M, K), w (K, N), optional bias (N). Output y (M, N).
void linear_backward(Node& n) {
  Node* x = n.in[0];
  Node* w = n.in[1];
  Node* b = n.in[2];
  const std::int64_t m = n.iparam[0], k = n.iparam[1], cols = n.iparam[2];
  // n.grad is final here, so its bf16 copy (where products run in bf16) serves both products.
  const auto gy = detail::final_grad(detail::operand(cmat(n.grad, m, cols)));
  bool fresh = false;
  if (float* gx = detail::grad_for_write(x, &fresh))
    detail::gemm(mat(gx, m, k), gy, held(operand(cmat(w->value, k, cols).transpose()), w), !fresh);
  if (float* gw = grad_of(w))
    detail::gemm(mat(gw, k, cols), held(operand(cmat(x->value, m, k).transpose()), x), gy, true);
  if (float* gb = grad_of(b)) mat(gb, 1, cols) += cmat(n.grad, m, cols).colwise().sum();
}

Tensor linear_impl(Tensor x, Tensor w, Tensor bias) {
  INDRIVE_CHECK(x.defined() && w.defined()) << "matmul of an undefined tensor";
  INDRIVE_CHECK_EQ(w.shape().rank, 2) << "weight must be 2-D, got " << w.shape().str();
  const std::int64_t k = w.dim(0), cols = w.dim(1);
  INDRIVE_CHECK_EQ(x.cols(), k) << "matmul " << x.shape().str() << " x " << w.shape().str();
  const std::int64_t m = x.rows();
  Graph& g = current_graph();
  Node* n = g.new_node(detail::with_last(x.shape(), cols));
  auto y = mat(n->value, m, cols);
  detail::gemm(y, held(operand(cmat(x.data(), m, k)), x.node()),
               held(operand(cmat(w.data(), k, cols)), w.node()), false);
  if (bias.defined()) {
    INDRIVE_CHECK_EQ(bias.numel(), cols) << "bias of shape " << bias.shape().str();
    y.rowwise() += cmat(bias.data(), 1, cols).row(0);
  }
  n->iparam[0] = m;
  n->iparam[1] = k;
  n->iparam[2] = cols;
  g.record(n, linear_backward, {x.node(), w.node(), bias.defined() ? bias.node() : nullptr});
  return Tensor(n);
}

// ---- linear_one_hot_tail ----
//
// n.saved holds x's first `from` columns as a contiguous (m, from) matrix (the dense product's
// operand, kept for the weight gradient), then the tail's ones as rows: m + 1 row offsets and
// the column of every one (int32, in float-sized slots). iparam: m, k, cols, from.

struct OneHotTail {
  const float* dense;
  const std::int32_t* offsets;
  const std::int32_t* columns;
};

OneHotTail tail_of(const Node& n) {
  const std::int64_t m = n.iparam[0], from = n.iparam[3];
  const auto* offsets = reinterpret_cast<const std::int32_t*>(n.saved + m * from);
  return {n.saved, offsets, offsets + m + 1};
}

// Splitting rows (forward) or output columns (weight gradient) over threads pays from about
// this many multiply-adds' worth of gathered additions.
constexpr std::int64_t kParallelGather = std::int64_t{1} << 17;

bool gather_in_parallel(std::int64_t work) {
  return work >= kParallelGather && omp_get_max_threads() > 1 && !omp_in_parallel();
}

// y[i] += sum of w's rows picked by row i's ones.
void gather_rows(float* y, const float* w, const OneHotTail& tail, std::int64_t m,
                 std::int64_t cols) {
  auto rows = [&](std::int64_t r0, std::int64_t r1) {
    for (std::int64_t i = r0; i < r1; ++i) {
      float* yi = y + i * cols;
      for (std::int32_t j = tail.offsets[i]; j < tail.offsets[i + 1]; ++j) {
        const float* wr = w + static_cast<std::int64_t>(tail.columns[j]) * cols;
#pragma omp simd
        for (std::int64_t c = 0; c < cols; ++c) yi[c] += wr[c];
      }
    }
  };
  if (!gather_in_parallel(static_cast<std::int64_t>(tail.offsets[m]) * cols)) {
    rows(0, m);
    return;
  }
  constexpr std::int64_t kRows = 32;
  const std::int64_t blocks = (m + kRows - 1) / kRows;
#pragma omp parallel for schedule(static)
  for (std::int64_t b = 0; b < blocks; ++b) rows(b * kRows, std::min(m, (b + 1) * kRows));
}

// gw[row picked by x's one] += gy[x's row], column block by column block so that threads never
// add into the same element and every element sums its rows in row order.
void scatter_rows(float* gw, const float* gy, const OneHotTail& tail, std::int64_t m,
                  std::int64_t cols) {
  auto block = [&](std::int64_t c0, std::int64_t c1) {
    for (std::int64_t i = 0; i < m; ++i) {
      const float* gi = gy + i * cols;
      for (std::int32_t j = tail.offsets[i]; j < tail.offsets[i + 1]; ++j) {
        float* wr = gw + static_cast<std::int64_t>(tail.columns[j]) * cols;
#pragma omp simd
        for (std::int64_t c = c0; c < c1; ++c) wr[c] += gi[c];
      }
    }
  };
  constexpr std::int64_t kCols = 64;
  const std::int64_t blocks = (cols + kCols - 1) / kCols;
  if (blocks == 1 || !gather_in_parallel(static_cast<std::int64_t>(tail.offsets[m]) * cols)) {
    block(0, cols);
    return;
  }
#pragma omp parallel for schedule(static)
  for (std::int64_t b = 0; b < blocks; ++b) block(b * kCols, std::min(cols, (b + 1) * kCols));
}

// Appends the columns in [from, k) of row x where it holds 1; false where it holds anything
// but 0 and 1. Eight columns at a time on AVX2 (a compare and a bit mask: one-hot blocks are
// mostly zeros), one at a time elsewhere.
bool find_ones_scalar(const float* x, std::int64_t from, std::int64_t k,
                      std::vector<std::int32_t>& out) {
  for (std::int64_t c = from; c < k; ++c) {
    if (x[c] == 1.0f) {
      out.push_back(static_cast<std::int32_t>(c));
    } else if (x[c] != 0.0f) {
      return false;
    }
  }
  return true;
}

#if defined(__x86_64__)
__attribute__((target("avx2,bmi"))) bool find_ones_avx2(const float* x, std::int64_t from,
                                                        std::int64_t k,
                                                        std::vector<std::int32_t>& out) {
  const __m256 one = _mm256_set1_ps(1.0f), zero = _mm256_setzero_ps();
  std::int64_t c = from;
  for (; c + 8 <= k; c += 8) {
    const __m256 v = _mm256_loadu_ps(x + c);
    auto is_one = static_cast<unsigned>(_mm256_movemask_ps(_mm256_cmp_ps(v, one, _CMP_EQ_OQ)));
    const auto is_zero =
        static_cast<unsigned>(_mm256_movemask_ps(_mm256_cmp_ps(v, zero, _CMP_EQ_OQ)));
    if ((is_one | is_zero) != 0xFFu) return false;
    while (is_one != 0) {
      out.push_back(static_cast<std::int32_t>(c + _tzcnt_u32(is_one)));
      is_one &= is_one - 1;
    }
  }
  return find_ones_scalar(x, c, k, out);
}
#endif

bool find_ones(const float* x, std::int64_t from, std::int64_t k, std::vector<std::int32_t>& out) {
#if defined(__x86_64__)
  if (one_hot_scan_vectorised()) return find_ones_avx2(x, from, k, out);
#endif
  return find_ones_scalar(x, from, k, out);
}

void linear_one_hot_tail_backward(Node& n) {
  Node* x = n.in[0];
  Node* w = n.in[1];
  Node* b = n.in[2];
  const std::int64_t m = n.iparam[0], k = n.iparam[1], cols = n.iparam[2], from = n.iparam[3];
  const OneHotTail tail = tail_of(n);
  const auto gy = detail::final_grad(detail::operand(cmat(n.grad, m, cols)));
  bool fresh = false;
  // The input's gradient is the full product, as linear's: the tail's ones may pass gradients
  // on (a straight-through sample), and gy * w^T is dense whatever x is.
  if (float* gx = detail::grad_for_write(x, &fresh))
    detail::gemm(mat(gx, m, k), gy, held(operand(cmat(w->value, k, cols).transpose()), w), !fresh);
  if (float* gw = grad_of(w)) {
    if (from > 0) {
      GemmOperand dense = operand(cmat(tail.dense, m, from).transpose());
      dense.lifetime = detail::Lifetime::kGraphValue;
      detail::gemm(mat(gw, from, cols), dense, gy, true);
    }
    scatter_rows(gw, n.grad, tail, m, cols);
  }
  if (float* gb = grad_of(b)) mat(gb, 1, cols) += cmat(n.grad, m, cols).colwise().sum();
}

}  // namespace

Tensor matmul(Tensor a, Tensor b) { return linear_impl(a, b, Tensor()); }
Tensor linear(Tensor x, Tensor w, Tensor bias) { return linear_impl(x, w, bias); }

Tensor linear_one_hot_tail(Tensor x, Tensor w, Tensor bias, std::int64_t one_hot_from) {
  INDRIVE_CHECK(x.defined() && w.defined()) << "matmul of an undefined tensor";
  INDRIVE_CHECK_EQ(w.shape().rank, 2) << "weight must be 2-D, got " << w.shape().str();
  const std::int64_t k = w.dim(0), cols = w.dim(1), from = one_hot_from;
  INDRIVE_CHECK_EQ(x.cols(), k) << "matmul " << x.shape().str() << " x " << w.shape().str();
  INDRIVE_CHECK(from >= 0 && from <= k)
      << "one-hot columns from " << from << " of an input with " << k;
  const std::int64_t m = x.rows();
  if (!gather_one_hot()) return linear_impl(x, w, bias);
  // The tail's ones, row by row; anything but 0 and 1 there means a dense product after all.
  thread_local std::vector<std::int32_t> row_offsets, ones;
  row_offsets.resize(static_cast<std::size_t>(m) + 1);
  ones.clear();
  const float* xv = x.data();
  for (std::int64_t i = 0; i < m; ++i) {
    row_offsets[i] = static_cast<std::int32_t>(ones.size());
    if (!find_ones(xv + i * k, from, k, ones)) return linear_impl(x, w, bias);
  }
  INDRIVE_CHECK(ones.size() <= static_cast<std::size_t>(std::numeric_limits<std::int32_t>::max()))
      << "too many ones";
  row_offsets[m] = static_cast<std::int32_t>(ones.size());
  Graph& g = current_graph();
  float* saved = g.alloc(m * from + m + 1 + static_cast<std::int64_t>(ones.size()));
  float* dense = saved;
  if (from > 0)
    for (std::int64_t i = 0; i < m; ++i) std::copy_n(xv + i * k, from, dense + i * from);
  auto* offsets = reinterpret_cast<std::int32_t*>(saved + m * from);
  std::copy(row_offsets.begin(), row_offsets.end(), offsets);
  std::copy(ones.begin(), ones.end(), offsets + m + 1);
  Node* n = g.new_node(detail::with_last(x.shape(), cols));
  n->saved = saved;
  n->iparam[0] = m;
  n->iparam[1] = k;
  n->iparam[2] = cols;
  n->iparam[3] = from;
  auto y = mat(n->value, m, cols);
  if (from > 0) {
    GemmOperand a = operand(cmat(dense, m, from));
    a.lifetime = detail::Lifetime::kGraphValue;
    detail::gemm(y, a, held(operand(cmat(w.data(), from, cols)), w.node()), false);
  } else {
    y.setZero();
  }
  gather_rows(n->value, w.data(), tail_of(*n), m, cols);
  if (bias.defined()) {
    INDRIVE_CHECK_EQ(bias.numel(), cols) << "bias of shape " << bias.shape().str();
    y.rowwise() += cmat(bias.data(), 1, cols).row(0);
  }
  g.record(n, linear_one_hot_tail_backward,
           {x.node(), w.node(), bias.defined() ? bias.node() : nullptr});
  return Tensor(n);
}

}  // namespace indrive::nn
