// Helpers shared by the op implementations (private to common/src/nn).
#pragma once

#include <omp.h>

#include <algorithm>
#include <cstdint>

#include "indrive/common/check.h"
#include "indrive/common/nn/tensor.h"

namespace indrive::nn::detail {

using Array = Eigen::Map<Eigen::ArrayXf>;
using ConstArray = Eigen::Map<const Eigen::ArrayXf>;

// The gradient buffer of an input, allocated zeroed on first use; nullptr when the input does
// not take a gradient.
inline float* grad_of(Node* n) {
  if (n == nullptr || !n->requires_grad) return nullptr;
  if (n->grad == nullptr) n->grad = current_graph().alloc_zeroed(n->shape.numel());
  return n->grad;
}

// Below this many elements, elementwise loops stay on one thread (a parallel region costs more).
inline constexpr std::int64_t kParallelMin = std::int64_t{1} << 16;
inline constexpr std::int64_t kChunk = std::int64_t{1} << 14;

// Calls fn(begin, end) over [0, n) in fixed chunks, in parallel when n is large. Chunk bounds do
// not depend on the thread count, so results are identical for any number of threads.
template <typename Fn>
void parallel_for(std::int64_t n, Fn&& fn) {
  if (n < kParallelMin || omp_get_max_threads() == 1 || omp_in_parallel()) {
    fn(std::int64_t{0}, n);
    return;
  }
  const std::int64_t chunks = (n + kChunk - 1) / kChunk;
#pragma omp parallel for schedule(static)
  for (std::int64_t c = 0; c < chunks; ++c) fn(c * kChunk, std::min(n, (c + 1) * kChunk));
}

// Row-major matrix views.
inline MatrixMap mat(float* p, std::int64_t rows, std::int64_t cols) {
  return MatrixMap(p, rows, cols);
}
inline ConstMatrixMap cmat(const float* p, std::int64_t rows, std::int64_t cols) {
  return ConstMatrixMap(p, rows, cols);
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
