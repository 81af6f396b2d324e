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
inline float* grad_of(Node* n) { return current_graph().grad_buffer(n); }

// The gradient buffer of an input for an op that writes every element: *fresh tells whether
// it is uninitialised (assign) or already holds contributions (accumulate).
inline float* grad_for_write(Node* n, bool* fresh) {
  return current_graph().grad_buffer_for_write(n, fresh);
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

// Products with at least this many multiply-adds are split over threads; smaller ones run on
// the calling thread, because a parallel region costs more than it saves (and much more when
// the machine is oversubscribed and idle threads spin).
inline constexpr std::int64_t kParallelGemmWork = std::int64_t{1} << 22;

// Runs Eigen's GEMM single-threaded: the engine splits large products itself (below), so that
// the thread count is ours to set and small products never open a parallel region.
inline void eigen_single_threaded() {
  static const bool once = (Eigen::setNbThreads(1), true);
  (void)once;
}

// dst (m, n) = a (m, k) * b (k, n), or += when `accumulate`. a and b may be transposed maps.
// Large products are split over output rows (or columns when there are few rows).
template <typename Dst, typename A, typename B>
void gemm(Dst&& dst, const A& a, const B& b, bool accumulate) {
  eigen_single_threaded();
  const std::int64_t m = dst.rows(), n = dst.cols(), k = a.cols();
  const int threads = omp_in_parallel() ? 1 : omp_get_max_threads();
  if (threads == 1 || m * n * k < kParallelGemmWork) {
    if (accumulate)
      dst.noalias() += a * b;
    else
      dst.noalias() = a * b;
    return;
  }
  const bool by_rows = m >= 64 * threads || m >= n;
  const std::int64_t extent = by_rows ? m : n;
  // A few parts per thread, handed out dynamically, so that a thread delayed by other jobs on
  // the machine does not hold the rest at the barrier. Parts split on multiples of 16 so that
  // each keeps full SIMD panels; every output element is computed by one part with the same
  // code whichever thread runs it, so results do not depend on the schedule.
  const std::int64_t parts =
      std::max<std::int64_t>(1, std::min<std::int64_t>(4 * threads, extent / 64));
  const std::int64_t part = ((extent + parts - 1) / parts + 15) / 16 * 16;
#pragma omp parallel for schedule(dynamic, 1) num_threads(threads)
  for (std::int64_t t = 0; t < parts; ++t) {
    const std::int64_t begin = std::min(extent, t * part);
    const std::int64_t len = std::min(extent, begin + part) - begin;
    if (len <= 0) continue;
    if (by_rows) {
      if (accumulate)
        dst.middleRows(begin, len).noalias() += a.middleRows(begin, len) * b;
      else
        dst.middleRows(begin, len).noalias() = a.middleRows(begin, len) * b;
    } else {
      if (accumulate)
        dst.middleCols(begin, len).noalias() += a * b.middleCols(begin, len);
      else
        dst.middleCols(begin, len).noalias() = a * b.middleCols(begin, len);
    }
  }
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
