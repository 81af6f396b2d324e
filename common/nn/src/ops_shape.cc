// Shape ops (reshape, concat, slice, stop_gradient) and reductions.
#include <algorithm>
#include <cstring>
#include <vector>

#include "indrive/nn/ops.h"
#include "ops_internal.h"

namespace indrive::nn {

using detail::grad_of;
using detail::Node;

Tensor reshape(Tensor x, const Shape& shape) {
  INDRIVE_CHECK_EQ(x.numel(), shape.numel())
      << "reshape " << x.shape().str() << " to " << shape.str();
  Graph& g = current_graph();
  Node* n = g.new_view_node(shape, x.data());
  g.link_view(n, x.node(), 0);
  return Tensor(n);
}

Tensor stop_gradient(Tensor x) {
  return Tensor(current_graph().new_view_node(x.shape(), x.data()));
}

// ---- Concat and slice ----
//
// Both view a tensor along `axis` as (outer, size, inner) blocks; iparam[0] is the axis.

namespace {

constexpr int kMaxConcat = 3;  // inputs recorded per node; longer lists are chained

void concat_backward(Node& n) {
  const int axis = static_cast<int>(n.iparam[0]);
  const std::int64_t outer = detail::outer_size(n.shape, axis);
  const std::int64_t inner = detail::inner_size(n.shape, axis);
  const std::int64_t total = n.shape.dims[axis] * inner;
  std::int64_t offset = 0;
  for (Node* part : n.in) {
    if (part == nullptr) break;
    const std::int64_t width = part->shape.dims[axis] * inner;
    bool fresh = false;
    if (float* gp = detail::grad_for_write(part, &fresh)) {
      for (std::int64_t o = 0; o < outer; ++o) {
        const float* src = n.grad + o * total + offset;
        float* dst = gp + o * width;
        if (fresh)
          std::memcpy(dst, src, width * sizeof(float));
        else
          for (std::int64_t i = 0; i < width; ++i) dst[i] += src[i];
      }
    }
    offset += width;
  }
}

Tensor concat_few(std::span<const Tensor> parts, int axis_in) {
  const Shape& first = parts[0].shape();
  const int axis = detail::normalize_axis(axis_in, first);
  Shape out = first;
  out.dims[axis] = 0;
  for (const Tensor& p : parts) {
    INDRIVE_CHECK_EQ(p.shape().rank, first.rank) << "concat of ranks";
    for (int d = 0; d < first.rank; ++d)
      INDRIVE_CHECK(d == axis || p.shape().dims[d] == first.dims[d])
          << "concat of " << first.str() << " and " << p.shape().str() << " on axis " << axis;
    out.dims[axis] += p.shape().dims[axis];
  }
  Graph& g = current_graph();
  Node* n = g.new_node(out);
  const std::int64_t outer = detail::outer_size(out, axis);
  const std::int64_t inner = detail::inner_size(out, axis);
  const std::int64_t total = out.dims[axis] * inner;
  std::int64_t offset = 0;
  for (const Tensor& p : parts) {
    const std::int64_t width = p.shape().dims[axis] * inner;
    for (std::int64_t o = 0; o < outer; ++o)
      std::memcpy(n->value + o * total + offset, p.data() + o * width, width * sizeof(float));
    offset += width;
  }
  n->iparam[0] = axis;
  // More than kMaxConcat parts only come here when no gradient is recorded.
  if (parts.size() <= static_cast<std::size_t>(kMaxConcat))
    g.record(n, concat_backward,
             {parts[0].node(), parts.size() > 1 ? parts[1].node() : nullptr,
              parts.size() > 2 ? parts[2].node() : nullptr});
  return Tensor(n);
}

}  // namespace

Tensor concat(std::span<const Tensor> parts, int axis) {
  INDRIVE_CHECK(!parts.empty()) << "concat of nothing";
  if (parts.size() <= static_cast<std::size_t>(kMaxConcat)) return concat_few(parts, axis);
  bool needs_grad = false;
  for (const Tensor& p : parts) needs_grad = needs_grad || p.requires_grad();
  if (!needs_grad || !current_graph().grad_enabled()) {
    // Nothing to record (e.g. imagination under no-grad): one copy into the result.
    return concat_few(parts, axis);
  }
  // Long lists (e.g. 64 time steps): concatenate in a balanced tree of small nodes, so the
  // copy cost stays O(n log n) and each node keeps its fixed input slots.
  std::vector<Tensor> level(parts.begin(), parts.end());
  while (level.size() > 1) {
    std::vector<Tensor> next;
    for (std::size_t i = 0; i < level.size(); i += kMaxConcat) {
      const std::size_t count = std::min<std::size_t>(kMaxConcat, level.size() - i);
      next.push_back(count == 1 ? level[i] : concat_few({level.data() + i, count}, axis));
    }
    level = std::move(next);
  }
  return level[0];
}

Tensor concat(std::initializer_list<Tensor> parts, int axis) {
  return concat(std::span<const Tensor>(parts.begin(), parts.size()), axis);
}

namespace {

void slice_backward(Node& n) {
  Node* x = n.in[0];
  float* gx = grad_of(x);
  if (gx == nullptr) return;
  const int axis = static_cast<int>(n.iparam[0]);
  const std::int64_t begin = n.iparam[1];
  const std::int64_t outer = detail::outer_size(x->shape, axis);
  const std::int64_t inner = detail::inner_size(x->shape, axis);
  const std::int64_t src_width = x->shape.dims[axis] * inner;
  const std::int64_t width = n.shape.dims[axis] * inner;
  for (std::int64_t o = 0; o < outer; ++o) {
    float* dst = gx + o * src_width + begin * inner;
    const float* src = n.grad + o * width;
    for (std::int64_t i = 0; i < width; ++i) dst[i] += src[i];
  }
}

}  // namespace

Tensor slice(Tensor x, std::int64_t begin, std::int64_t end, int axis_in) {
  const int axis = detail::normalize_axis(axis_in, x.shape());
  INDRIVE_CHECK(0 <= begin && begin < end && end <= x.shape().dims[axis])
      << "slice [" << begin << ", " << end << ") of axis " << axis << " of " << x.shape().str();
  Shape out = x.shape();
  out.dims[axis] = end - begin;
  Graph& g = current_graph();
  const std::int64_t outer = detail::outer_size(out, axis);
  const std::int64_t inner = detail::inner_size(out, axis);
  const std::int64_t src_width = x.shape().dims[axis] * inner;
  const std::int64_t width = out.dims[axis] * inner;
  if (outer == 1) {
    // Contiguous: a view with no copy, sharing the source's gradient.
    Node* n = g.new_view_node(out, x.data() + begin * inner);
    g.link_view(n, x.node(), begin * inner);
    return Tensor(n);
  }
  Node* n = g.new_node(out);
  {
    for (std::int64_t o = 0; o < outer; ++o)
      std::memcpy(n->value + o * width, x.data() + o * src_width + begin * inner,
                  width * sizeof(float));
  }
  n->iparam[0] = axis;
  n->iparam[1] = begin;
  g.record(n, slice_backward, {x.node()});
  return Tensor(n);
}

// ---- Reductions ----

namespace {

// iparam: outer, size, inner; fparam[0]: factor (1 for sum, 1/size for mean).
void reduce_backward(Node& n) {
  bool fresh = false;
  float* gx = detail::grad_for_write(n.in[0], &fresh);
  if (gx == nullptr) return;
  const std::int64_t outer = n.iparam[0], size = n.iparam[1], inner = n.iparam[2];
  const float f = n.fparam[0];
  if (inner == 1) {
    // Rows broadcast their one gradient value (the common case: sums over the last axis).
    // Row by row over each chunk: no division per element.
    detail::parallel_for(outer * size, [&](std::int64_t s, std::int64_t e) {
      for (std::int64_t i = s; i < e;) {
        const std::int64_t row = i / size, end = std::min(e, (row + 1) * size);
        const float v = f * n.grad[row];
        if (fresh)
          std::fill(gx + i, gx + end, v);
        else
          for (std::int64_t j = i; j < end; ++j) gx[j] += v;
        i = end;
      }
    });
    return;
  }
  if (fresh) std::fill_n(gx, outer * size * inner, 0.0f);
  for (std::int64_t o = 0; o < outer; ++o)
    for (std::int64_t k = 0; k < size; ++k) {
      float* dst = gx + (o * size + k) * inner;
      const float* src = n.grad + o * inner;
      for (std::int64_t i = 0; i < inner; ++i) dst[i] += f * src[i];
    }
}

Tensor reduce(Tensor x, std::int64_t outer, std::int64_t size, std::int64_t inner, const Shape& out,
              float factor) {
  Graph& g = current_graph();
  Node* n = g.new_node(out);
  const float* xv = x.data();
  if (inner == 1) {
    // Contiguous rows: vectorised row sums.
    auto y = detail::mat(n->value, outer, 1);
    y.noalias() = detail::cmat(xv, outer, size).rowwise().sum() * factor;
  } else {
    for (std::int64_t o = 0; o < outer; ++o) {
      float* dst = n->value + o * inner;
      std::fill_n(dst, inner, 0.0f);
      for (std::int64_t k = 0; k < size; ++k) {
        const float* src = xv + (o * size + k) * inner;
        for (std::int64_t i = 0; i < inner; ++i) dst[i] += src[i];
      }
      for (std::int64_t i = 0; i < inner; ++i) dst[i] *= factor;
    }
  }
  n->iparam[0] = outer;
  n->iparam[1] = size;
  n->iparam[2] = inner;
  n->fparam[0] = factor;
  g.record(n, reduce_backward, {x.node()});
  return Tensor(n);
}

Tensor reduce_axis(Tensor x, int axis_in, bool average) {
  const int axis = detail::normalize_axis(axis_in, x.shape());
  const Shape& s = x.shape();
  Shape out;
  out.rank = s.rank - 1;
  for (int i = 0, j = 0; i < s.rank; ++i)
    if (i != axis) out.dims[j++] = s.dims[i];
  const std::int64_t size = s.dims[axis];
  return reduce(x, detail::outer_size(s, axis), size, detail::inner_size(s, axis), out,
                average ? 1.0f / static_cast<float>(size) : 1.0f);
}

}  // namespace

Tensor sum(Tensor x) { return reduce(x, 1, x.numel(), 1, Shape(), 1.0f); }
Tensor mean(Tensor x) {
  return reduce(x, 1, x.numel(), 1, Shape(), 1.0f / static_cast<float>(x.numel()));
}
Tensor sum(Tensor x, int axis) { return reduce_axis(x, axis, false); }
Tensor mean(Tensor x, int axis) { return reduce_axis(x, axis, true); }

}  // namespace indrive::nn
