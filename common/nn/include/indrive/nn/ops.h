// Differentiable ops. Every op allocates its result in the current graph and, when grad mode is
// on and an input requires a gradient, records its backward rule.
//
// Conventions: tensors are row-major; a tensor of shape (d0, ..., dk) is also viewed as a matrix
// (rows = d0 * ... * d(k-1), cols = dk). Images are NHWC: (N, H, W, C). "Broadcasting" means
// the matrix view of an operand may have 1 row and/or 1 column and is repeated to match.
#pragma once

#include <cstdint>
#include <initializer_list>
#include <span>

#include "indrive/nn/tensor.h"

namespace indrive::nn {

// ---- Linear algebra ----

// Matrix product. a is (..., K) viewed as (M, K); b is (K, N); result is (..., N).
Tensor matmul(Tensor a, Tensor b);
// x * w + bias. x is (..., in); w is (in, out); bias is (out) or undefined; result (..., out).
Tensor linear(Tensor x, Tensor w, Tensor bias = {});
// linear(x, w, bias) for an x whose columns from `one_hot_from` on hold only zeros and ones
// (the one-hot latents and actions after a model state's dense part): those columns' share of
// the product is a sum of the rows of w they pick, so it is gathered, not multiplied, and their
// share of w's gradient is scattered the same way. The same function as linear(); the result
// differs from it only by the order of additions (and, with bf16 products, by the picked rows
// staying fp32). When the columns hold anything else it runs linear() itself.
Tensor linear_one_hot_tail(Tensor x, Tensor w, Tensor bias, std::int64_t one_hot_from);

// ---- Elementwise binary ops with broadcasting of the (rows, cols) views ----

// a + b; a and b are (R, C), (1, C), (R, 1) or (1, 1) views; result has the larger shape.
Tensor add(Tensor a, Tensor b);
// a - b, broadcasting as add.
Tensor sub(Tensor a, Tensor b);
// a * b (elementwise), broadcasting as add.
Tensor mul(Tensor a, Tensor b);
// a / b (elementwise), broadcasting as add.
Tensor div(Tensor a, Tensor b);

// ---- Scalar ops ----

// x * s.
Tensor scale(Tensor x, float s);
// x + c.
Tensor add_scalar(Tensor x, float c);
// c - x.
Tensor rsub_scalar(float c, Tensor x);

inline Tensor operator+(Tensor a, Tensor b) { return add(a, b); }
inline Tensor operator-(Tensor a, Tensor b) { return sub(a, b); }
inline Tensor operator*(Tensor a, Tensor b) { return mul(a, b); }
inline Tensor operator/(Tensor a, Tensor b) { return div(a, b); }
inline Tensor operator*(Tensor a, float s) { return scale(a, s); }
inline Tensor operator*(float s, Tensor a) { return scale(a, s); }
inline Tensor operator+(Tensor a, float c) { return add_scalar(a, c); }
inline Tensor operator-(Tensor a, float c) { return add_scalar(a, -c); }
inline Tensor operator-(float c, Tensor a) { return rsub_scalar(c, a); }
inline Tensor operator-(Tensor a) { return scale(a, -1.0f); }

// ---- Elementwise unary ops (result has the shape of x) ----

// x * sigmoid(x).
Tensor silu(Tensor x);
// x for x > 0, exp(x) - 1 otherwise.
Tensor elu(Tensor x);
// max(x, 0).
Tensor relu(Tensor x);
// 1 / (1 + exp(-x)).
Tensor sigmoid(Tensor x);
// tanh(x).
Tensor tanh(Tensor x);
// exp(x).
Tensor exp(Tensor x);
// log(x); x must be positive.
Tensor log(Tensor x);
// x * x.
Tensor square(Tensor x);
// sqrt(x); x must be positive.
Tensor sqrt(Tensor x);
// log(1 + exp(x)), computed stably.
Tensor softplus(Tensor x);
// sign(x) * log(1 + |x|) (DreamerV3's symlog).
Tensor symlog(Tensor x);
// sign(x) * (exp(|x|) - 1), the inverse of symlog.
Tensor symexp(Tensor x);
// Clamps x to [lo, hi]; the gradient is zero where x was clamped.
Tensor clamp(Tensor x, float lo, float hi);
// max(x, c); the gradient is zero where x < c (free bits).
Tensor maximum(Tensor x, float c);
// The value of x with no gradient flowing back (shares x's memory).
Tensor stop_gradient(Tensor x);

// ---- Shape ops ----

// Same values in a new shape with the same number of elements (a copy-free view).
Tensor reshape(Tensor x, const Shape& shape);
// Joins tensors along `axis` (negative counts from the end); other dimensions must match.
Tensor concat(std::span<const Tensor> parts, int axis = -1);
Tensor concat(std::initializer_list<Tensor> parts, int axis = -1);
// Elements [begin, end) of `axis`; the result keeps the rank of x.
Tensor slice(Tensor x, std::int64_t begin, std::int64_t end, int axis = -1);

// ---- Reductions ----

// Sum of all elements; a scalar (rank 0).
Tensor sum(Tensor x);
// Mean of all elements; a scalar.
Tensor mean(Tensor x);
// Sum over one axis, which is removed from the shape (rank-1 input gives a scalar).
Tensor sum(Tensor x, int axis);
// Mean over one axis, which is removed from the shape.
Tensor mean(Tensor x, int axis);

// ---- Normalisation and softmax over the last axis ----

// (x - mean) / sqrt(var + eps) * gamma + beta over the last axis. x is (..., C); gamma and
// beta are (C) or undefined. DreamerV3 uses eps = 1e-3. For NHWC feature maps this is the
// channel LayerNorm.
Tensor layer_norm(Tensor x, Tensor gamma, Tensor beta, float eps = 1e-3f);
// silu(layer_norm(x, gamma, beta, eps)) as one op: the norm's output is recomputed in the
// backward pass instead of stored (saves memory traffic on large conv feature maps).
Tensor layer_norm_silu(Tensor x, Tensor gamma, Tensor beta, float eps = 1e-3f);
// Softmax over the last axis. For 32 groups of 32 classes, reshape (B, 1024) to (B, 32, 32).
Tensor softmax(Tensor x);
// Log-softmax over the last axis.
Tensor log_softmax(Tensor x);

// ---- Convolutions (NHWC) ----

// Geometry of a 2-D convolution; DreamerV3's conv stacks use kernel 4, stride 2, padding 1.
struct ConvGeometry {
  int kernel = 4;
  int stride = 2;
  int padding = 1;
};

// 2-D convolution. x is (N, H, W, C); w is (K*K*C, O) with rows ordered (ky, kx, c); bias is
// (O) or undefined. Result is (N, OH, OW, O), OH = (H + 2p - K) / s + 1.
Tensor conv2d(Tensor x, Tensor w, Tensor bias = {}, ConvGeometry g = {});
// Transposed 2-D convolution (the adjoint of conv2d with the same geometry). x is (N, H, W, C);
// w is (C, K*K*O) with columns ordered (ky, kx, o); bias is (O) or undefined. Result is
// (N, OH, OW, O), OH = (H - 1) * s - 2p + K.
Tensor conv_transpose2d(Tensor x, Tensor w, Tensor bias = {}, ConvGeometry g = {});

// ---- Distributions and losses ----

// Categorical probabilities with a uniform mix: (1 - mix) * softmax + mix / classes, per group.
// logits is (..., G * classes); result has the same shape.
Tensor unimix_probs(Tensor logits, int classes, float mix = 0.01f);
// Straight-through sample: one_hot(sample) + probs - stop_gradient(probs). probs is
// (..., G * classes); result has the same shape; its value is one-hot per group and its
// gradient is the identity to probs. Draws one number per group from rng.
Tensor sample_straight_through(Tensor probs, int classes, Rng& rng);
// The one-hot of the most likely class per group (no gradient); probs is (..., G * classes).
Tensor mode_one_hot(Tensor probs, int classes);
// KL(p || q) = sum p * (log p - log q), summed over all groups of the last axis. p and q are
// (..., G * classes) probabilities with no zeros (use unimix_probs); result is (...).
Tensor kl_categorical(Tensor p, Tensor q);
// Entropy -sum p log p over the last axis; p is (..., C) with no zeros; result is (...).
Tensor entropy(Tensor p);

// Number of bins of the two-hot encoding and its range in symlog space (DreamerV3).
inline constexpr int kTwoHotBins = 255;
inline constexpr float kTwoHotLow = -20.0f;
inline constexpr float kTwoHotHigh = 20.0f;
// Two-hot encoding of symlog(target) over kTwoHotBins bins in [low, high]; no gradient.
// target is (R) or (R, 1); result is (R, kTwoHotBins).
Tensor twohot(Tensor target);
// Cross-entropy -sum twohot(target) * log_softmax(logits). logits is (R, kTwoHotBins); target
// is (R) or (R, 1) and gets no gradient; result is (R).
Tensor twohot_cross_entropy(Tensor logits, Tensor target);
// The prediction of two-hot logits: symexp(sum softmax(logits) * bins). logits is
// (R, kTwoHotBins); result is (R).
Tensor twohot_mean(Tensor logits);
// Binary cross-entropy with logits, elementwise: max(x, 0) - x * t + log(1 + exp(-|x|)).
// logits and target have the same shape; target gets no gradient.
Tensor bce_with_logits(Tensor logits, Tensor target);
// Squared error (pred - target)^2 elementwise; target gets no gradient.
Tensor squared_error(Tensor pred, Tensor target);
// Mean squared error over all elements; a scalar.
Tensor mse(Tensor pred, Tensor target);

}  // namespace indrive::nn
