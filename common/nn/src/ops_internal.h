// Helpers shared by the op implementations (private to common/nn/src).
#pragma once

#include <omp.h>

#include <algorithm>
#include <cstdint>

#include "indrive/basics/check.h"
#include "indrive/nn/kernels.h"
#include "indrive/nn/tensor.h"

namespace indrive::nn::detail {

using Array = Eigen::Map<Eigen::ArrayXf>;
using ConstArray = Eigen::Map<const Eigen::ArrayXf>;

// The gradient buffer of an input, allocated zeroed on first use; nullptr when the input does
// not take a gradient.
inline float* grad_of(Node* n) { return gradient_graph().grad_buffer(n); }

// The gradient buffer of an input for an op that writes every element: *fresh tells whether
// it is uninitialised (assign) or already holds contributions (accumulate).
inline float* grad_for_write(Node* n, bool* fresh) {
  return gradient_graph().grad_buffer_for_write(n, fresh);
}

// Below this many elements, elementwise loops stay on one thread (a parallel region costs more).
inline constexpr std::int64_t kParallelMin = std::int64_t{1} << 16;
inline constexpr std::int64_t kChunk = std::int64_t{1} << 14;

// Calls fn(begin, end) over [0, n) in fixed chunks, in parallel when n is large. Chunk bounds do
// not depend on the thread count, so results are identical for any number of threads. Chunks
// are handed out dynamically: on a machine shared with other jobs a thread that was descheduled
// then does less, instead of holding the others at the barrier.
template <typename Fn>
void parallel_for(std::int64_t n, Fn&& fn) {
  if (n < kParallelMin || omp_get_max_threads() == 1 || omp_in_parallel()) {
    fn(std::int64_t{0}, n);
    return;
  }
  const std::int64_t chunks = (n + kChunk - 1) / kChunk;
#pragma omp parallel for schedule(dynamic, 1)
  for (std::int64_t c = 0; c < chunks; ++c) fn(c * kChunk, std::min(n, (c + 1) * kChunk));
}

// Row-major matrix views.
inline MatrixMap mat(float* p, std::int64_t rows, std::int64_t cols) {
  return MatrixMap(p, rows, cols);
}
inline ConstMatrixMap cmat(const float* p, std::int64_t rows, std::int64_t cols) {
  return ConstMatrixMap(p, rows, cols);
}

// An operand of a product as the kernel layer takes it: a row-major map, or the transpose of one.
inline GemmOperand operand(const ConstMatrixMap& m) {
  return {m.data(), m.rows(), m.cols(), false};
}
template <typename Map>
GemmOperand operand(const Eigen::Transpose<Map>& t) {
  const auto& m = t.nestedExpression();
  return {m.data(), m.cols(), m.rows(), true};
}

// The operand of a node's value (or of its gradient, once final) with the lifetime its bf16
// copy may be kept for: a parameter's (or a view of one) per version, any other node's per
// graph.
inline GemmOperand held(GemmOperand op, const Node* node) {
  const Node* root = node;
  while (root->view_of != nullptr) root = root->view_of;
  if (root->persistent) {
    op.lifetime = Lifetime::kVersioned;
    op.version = &root->version;
  } else {
    op.lifetime = Lifetime::kGraphValue;
  }
  return op;
}
// The operand of a gradient buffer that is final (the node's own, in its backward).
inline GemmOperand final_grad(GemmOperand op) {
  op.lifetime = Lifetime::kGraphValue;
  return op;
}

// dst (m, n) = a (m, k) * b (k, n), or += when `accumulate`. a and b may be transposed maps
// (or operands made from them); the product runs in the kernel layer (kernels.h).
inline GemmOperand operand(const GemmOperand& op) { return op; }
template <typename Dst, typename A, typename B>
void gemm(Dst&& dst, const A& a, const B& b, bool accumulate) {
  const GemmOperand ga = operand(a), gb = operand(b);
  INDRIVE_CHECK(dst.rows() == ga.rows && dst.cols() == gb.cols) << "product destination shape";
  gemm(dst.data(), ga, gb, accumulate);
}

// Normalises a possibly negative axis and checks it.
inline int normalize_axis(int axis, const Shape& shape) {
  const int a = axis < 0 ? axis + shape.rank : axis;
  INDRIVE_CHECK(a >= 0 && a < shape.rank)
      << "axis " << axis << " out of range for shape " << shape.str();
  return a;
}

// Product of the dimensions before and after `axis`.
inline std::int64_t outer_size(const Shape& s, int axis) {
  std::int64_t n = 1;
  for (int i = 0; i < axis; ++i) n *= s.dims[i];
  return n;
}
inline std::int64_t inner_size(const Shape& s, int axis) {
  std::int64_t n = 1;
  for (int i = axis + 1; i < s.rank; ++i) n *= s.dims[i];
  return n;
}

// A shape with its last dimension replaced.
inline Shape with_last(const Shape& s, std::int64_t last) {
  Shape r = s;
  if (r.rank == 0) {
    r.rank = 1;
  }
  r.dims[r.rank - 1] = last;
  return r;
}

}  // namespace indrive::nn::detail
