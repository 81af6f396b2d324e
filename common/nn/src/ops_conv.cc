// NHWC convolution and transposed convolution as im2col + GEMM (the products in the kernel
// layer, kernels.h). oneDNN's own convolution primitives were measured in their place
// (docs/performance.md, "Kernel layer") and were not faster over a whole update.
//
// Both ops relate a "big" grid (Hb, Wb) and a "small" grid (Hs, Ws) by
//   big = small * stride - padding + kernel_offset,
// so one im2col (big -> rows of the small grid) and its adjoint col2im serve both: conv2d is
// im2col then GEMM, its input gradient is GEMM then col2im; conv_transpose2d is the reverse.
// Images are processed in chunks so the column buffer stays small (and is reused per thread).
#include <algorithm>
#include <cstring>
#include <vector>

#include "indrive/nn/ops.h"
#include "ops_internal.h"

namespace indrive::nn {

using detail::cmat;
using detail::grad_of;
using detail::mat;
using detail::Node;

namespace {

struct Grid {
  std::int64_t n, hb, wb, hs, ws, c;  // images, big grid, small grid, channels of the big side
  int k, stride, pad;
  std::int64_t rows_per_image() const { return hs * ws; }
  std::int64_t patch() const { return static_cast<std::int64_t>(k) * k * c; }
};

// cols (images * Hs * Ws, K*K*C) <- patches of big (images, Hb, Wb, C) for `images` images.
// Images are independent, so both loops split over them when the work is large.
bool parallel_images(const Grid& g, std::int64_t images) {
  return images > 1 && images * g.rows_per_image() * g.patch() >= detail::kParallelMin &&
         omp_get_max_threads() > 1 && !omp_in_parallel();
}

void im2col(const Grid& g, const float* big, std::int64_t images, float* cols) {
  const std::int64_t patch = g.patch();
  const std::int64_t c = g.c;
#pragma omp parallel for schedule(dynamic, 4) if (parallel_images(g, images))
  for (std::int64_t i = 0; i < images; ++i) {
    const float* img = big + i * g.hb * g.wb * c;
    for (std::int64_t sy = 0; sy < g.hs; ++sy)
      for (std::int64_t sx = 0; sx < g.ws; ++sx) {
        float* row = cols + ((i * g.hs + sy) * g.ws + sx) * patch;
        for (int ky = 0; ky < g.k; ++ky) {
          const std::int64_t by = sy * g.stride - g.pad + ky;
          float* dst = row + static_cast<std::int64_t>(ky) * g.k * c;
          if (by < 0 || by >= g.hb) {
            std::memset(dst, 0, g.k * c * sizeof(float));
            continue;
          }
          // The kernel row's taps inside the image are one contiguous run of the image row
          // (kx0 <= kx < kx1): one copy instead of one small call per tap (C is 3 to 16 floats).
          const std::int64_t bx0 = sx * g.stride - g.pad;
          const std::int64_t kx0 = std::max<std::int64_t>(0, -bx0);
          const std::int64_t kx1 = std::min<std::int64_t>(g.k, g.wb - bx0);
          if (kx0 >= kx1) {
            std::memset(dst, 0, g.k * c * sizeof(float));
            continue;
          }
          if (kx0 > 0) std::memset(dst, 0, kx0 * c * sizeof(float));
          std::memcpy(dst + kx0 * c, img + (by * g.wb + bx0 + kx0) * c,
                      (kx1 - kx0) * c * sizeof(float));
          if (kx1 < g.k) std::memset(dst + kx1 * c, 0, (g.k - kx1) * c * sizeof(float));
        }
      }
  }
}

// big (images, Hb, Wb, C) += scatter of cols (images * Hs * Ws, K*K*C).
void col2im(const Grid& g, const float* cols, std::int64_t images, float* big) {
  const std::int64_t patch = g.patch();
  const std::int64_t c = g.c;
#pragma omp parallel for schedule(dynamic, 4) if (parallel_images(g, images))
  for (std::int64_t i = 0; i < images; ++i) {
    float* img = big + i * g.hb * g.wb * c;
    for (std::int64_t sy = 0; sy < g.hs; ++sy)
      for (std::int64_t sx = 0; sx < g.ws; ++sx) {
        const float* row = cols + ((i * g.hs + sy) * g.ws + sx) * patch;
        for (int ky = 0; ky < g.k; ++ky) {
          const std::int64_t by = sy * g.stride - g.pad + ky;
          if (by < 0 || by >= g.hb) continue;
          // As in im2col, the taps inside the image are one contiguous run.
          const std::int64_t bx0 = sx * g.stride - g.pad;
          const std::int64_t kx0 = std::max<std::int64_t>(0, -bx0);
          const std::int64_t kx1 = std::min<std::int64_t>(g.k, g.wb - bx0);
          if (kx0 >= kx1) continue;
          const float* src = row + (static_cast<std::int64_t>(ky) * g.k + kx0) * c;
          float* dst = img + (by * g.wb + bx0 + kx0) * c;
          const std::int64_t len = (kx1 - kx0) * c;
          for (std::int64_t e = 0; e < len; ++e) dst[e] += src[e];
        }
      }
  }
}

// A per-thread scratch buffer that only grows, so steady-state steps do not allocate.
float* scratch(std::size_t n) {
  thread_local std::vector<float> buffer;
  if (buffer.size() < n) buffer.resize(n);
  return buffer.data();
}

// Images per chunk: keep the column buffer near 4 M floats but at least one image.
std::int64_t chunk_images(const Grid& g) {
  const std::int64_t per_image = g.rows_per_image() * g.patch();
  return std::max<std::int64_t>(1,
                                std::min<std::int64_t>(g.n, (std::int64_t{4} << 20) / per_image));
}

// iparam: n, hb, wb, hs, ws, c(big), k | stride<<16 | pad<<32, out channels.
void store(Node* node, const Grid& g, std::int64_t oc) {
  node->iparam[0] = g.n;
  node->iparam[1] = g.hb;
  node->iparam[2] = g.wb;
  node->iparam[3] = g.hs;
  node->iparam[4] = g.ws;
  node->iparam[5] = g.c;
  node->iparam[6] =
      g.k | (static_cast<std::int64_t>(g.stride) << 16) | (static_cast<std::int64_t>(g.pad) << 32);
  node->iparam[7] = oc;
}

Grid load(const Node& node) {
  Grid g;
  g.n = node.iparam[0];
  g.hb = node.iparam[1];
  g.wb = node.iparam[2];
  g.hs = node.iparam[3];
  g.ws = node.iparam[4];
  g.c = node.iparam[5];
  g.k = static_cast<int>(node.iparam[6] & 0xffff);
  g.stride = static_cast<int>((node.iparam[6] >> 16) & 0xffff);
  g.pad = static_cast<int>((node.iparam[6] >> 32) & 0xffff);
  return g;
}

void add_bias(float* y, const float* bias, std::int64_t rows, std::int64_t cols) {
  mat(y, rows, cols).rowwise() += cmat(bias, 1, cols).row(0);
}

void bias_grad(const float* gy, float* gb, std::int64_t rows, std::int64_t cols) {
  mat(gb, 1, cols) += cmat(gy, rows, cols).colwise().sum();
}

// conv2d: big = input x (N, Hb, Wb, C); small = output (N, Hs, Ws, O); w (K*K*C, O).
void conv2d_backward(Node& n) {
  const Grid g = load(n);
  const std::int64_t oc = n.iparam[7];
  Node* x = n.in[0];
  Node* w = n.in[1];
  float* gx = grad_of(x);
  float* gw = grad_of(w);
  if (float* gb = grad_of(n.in[2])) bias_grad(n.grad, gb, n.shape.rows(), oc);
  const std::int64_t patch = g.patch();
  const std::int64_t chunk = chunk_images(g);
  float* cols = scratch(static_cast<std::size_t>(chunk * g.rows_per_image() * patch));
  for (std::int64_t i0 = 0; i0 < g.n; i0 += chunk) {
    const std::int64_t images = std::min(chunk, g.n - i0);
    const std::int64_t rows = images * g.rows_per_image();
    const auto gy =
        detail::final_grad(detail::operand(cmat(n.grad + i0 * g.rows_per_image() * oc, rows, oc)));
    if (gw) {
      im2col(g, x->value + i0 * g.hb * g.wb * g.c, images, cols);
      detail::gemm(mat(gw, patch, oc), cmat(cols, rows, patch).transpose(), gy, true);
    }
    if (gx) {
      detail::gemm(mat(cols, rows, patch), gy,
                   detail::held(detail::operand(cmat(w->value, patch, oc).transpose()), w), false);
      col2im(g, cols, images, gx + i0 * g.hb * g.wb * g.c);
    }
  }
}

// conv_transpose2d: small = input x (N, Hs, Ws, C); big = output (N, Hb, Wb, O);
// w (C, K*K*O). Grid.c holds O (the big side's channels).
void conv_transpose2d_backward(Node& n) {
  const Grid g = load(n);
  const std::int64_t ic = n.iparam[7];
  Node* x = n.in[0];
  Node* w = n.in[1];
  bool fresh = false;
  float* gx = detail::grad_for_write(x, &fresh);
  float* gw = grad_of(w);
  if (float* gb = grad_of(n.in[2])) bias_grad(n.grad, gb, n.shape.rows(), g.c);
  const std::int64_t patch = g.patch();
  const std::int64_t chunk = chunk_images(g);
  float* cols = scratch(static_cast<std::size_t>(chunk * g.rows_per_image() * patch));
  for (std::int64_t i0 = 0; i0 < g.n; i0 += chunk) {
    const std::int64_t images = std::min(chunk, g.n - i0);
    const std::int64_t rows = images * g.rows_per_image();
    im2col(g, n.grad + i0 * g.hb * g.wb * g.c, images, cols);
    auto gcols = cmat(cols, rows, patch);
    const auto xin = detail::held(
        detail::operand(cmat(x->value + i0 * g.rows_per_image() * ic, rows, ic).transpose()), x);
    if (gw) detail::gemm(mat(gw, ic, patch), xin, gcols, true);
    if (gx)
      detail::gemm(mat(gx + i0 * g.rows_per_image() * ic, rows, ic), gcols,
                   detail::held(detail::operand(cmat(w->value, ic, patch).transpose()), w), !fresh);
  }
}

}  // namespace

Tensor conv2d(Tensor x, Tensor w, Tensor bias, ConvGeometry geom) {
  INDRIVE_CHECK_EQ(x.shape().rank, 4)
      << "conv2d input must be (N, H, W, C), got " << x.shape().str();
  Grid g;
  g.n = x.dim(0);
  g.hb = x.dim(1);
  g.wb = x.dim(2);
  g.c = x.dim(3);
  g.k = geom.kernel;
  g.stride = geom.stride;
  g.pad = geom.padding;
  g.hs = (g.hb + 2 * g.pad - g.k) / g.stride + 1;
  g.ws = (g.wb + 2 * g.pad - g.k) / g.stride + 1;
  const std::int64_t patch = g.patch();
  INDRIVE_CHECK(w.shape().rank == 2 && w.dim(0) == patch)
      << "conv2d weight must be (K*K*C = " << patch << ", O), got " << w.shape().str();
  const std::int64_t oc = w.dim(1);
  Graph& graph = current_graph();
  Node* n = graph.new_node(Shape{g.n, g.hs, g.ws, oc});
  const std::int64_t chunk = chunk_images(g);
  float* cols = scratch(static_cast<std::size_t>(chunk * g.rows_per_image() * patch));
  for (std::int64_t i0 = 0; i0 < g.n; i0 += chunk) {
    const std::int64_t images = std::min(chunk, g.n - i0);
    const std::int64_t rows = images * g.rows_per_image();
    im2col(g, x.data() + i0 * g.hb * g.wb * g.c, images, cols);
    detail::gemm(mat(n->value + i0 * g.rows_per_image() * oc, rows, oc), cmat(cols, rows, patch),
                 detail::held(detail::operand(cmat(w.data(), patch, oc)), w.node()), false);
  }
  if (bias.defined()) {
    INDRIVE_CHECK_EQ(bias.numel(), oc) << "conv2d bias";
    add_bias(n->value, bias.data(), n->shape.rows(), oc);
  }
  store(n, g, oc);
  graph.record(n, conv2d_backward, {x.node(), w.node(), bias.defined() ? bias.node() : nullptr});
  return Tensor(n);
}

Tensor conv_transpose2d(Tensor x, Tensor w, Tensor bias, ConvGeometry geom) {
  INDRIVE_CHECK_EQ(x.shape().rank, 4)
      << "conv_transpose2d input must be (N, H, W, C), got " << x.shape().str();
  const std::int64_t ic = x.dim(3);
  const std::int64_t kk = static_cast<std::int64_t>(geom.kernel) * geom.kernel;
  INDRIVE_CHECK(w.shape().rank == 2 && w.dim(0) == ic && w.dim(1) % kk == 0)
      << "conv_transpose2d weight must be (C = " << ic << ", K*K*O), got " << w.shape().str();
  Grid g;
  g.n = x.dim(0);
  g.hs = x.dim(1);
  g.ws = x.dim(2);
  g.c = w.dim(1) / kk;
  g.k = geom.kernel;
  g.stride = geom.stride;
  g.pad = geom.padding;
  g.hb = (g.hs - 1) * g.stride - 2 * g.pad + g.k;
  g.wb = (g.ws - 1) * g.stride - 2 * g.pad + g.k;
  const std::int64_t patch = g.patch();
  Graph& graph = current_graph();
  Node* n = graph.new_node(Shape{g.n, g.hb, g.wb, g.c});
  std::memset(n->value, 0, n->shape.numel() * sizeof(float));
  const std::int64_t chunk = chunk_images(g);
  float* cols = scratch(static_cast<std::size_t>(chunk * g.rows_per_image() * patch));
  for (std::int64_t i0 = 0; i0 < g.n; i0 += chunk) {
    const std::int64_t images = std::min(chunk, g.n - i0);
    const std::int64_t rows = images * g.rows_per_image();
    detail::gemm(
        mat(cols, rows, patch),
        detail::held(detail::operand(cmat(x.data() + i0 * g.rows_per_image() * ic, rows, ic)),
                     x.node()),
        detail::held(detail::operand(cmat(w.data(), ic, patch)), w.node()), false);
    col2im(g, cols, images, n->value + i0 * g.hb * g.wb * g.c);
  }
  if (bias.defined()) {
    INDRIVE_CHECK_EQ(bias.numel(), g.c) << "conv_transpose2d bias";
    add_bias(n->value, bias.data(), n->shape.rows(), g.c);
  }
  store(n, g, ic);
  graph.record(n, conv_transpose2d_backward,
               {x.node(), w.node(), bias.defined() ? bias.node() : nullptr});
  return Tensor(n);
}

}  // namespace indrive::nn
