// Layers: Linear, LayerNorm, MLP, GRU cell, conv encoder and decoder, and initialisation.
#include "indrive/nn/layers.h"

#include <cmath>

#include "indrive/basics/check.h"

namespace indrive::nn {

Tensor activate(Tensor x, Act act) {
  switch (act) {
    case Act::kNone:
      return x;
    case Act::kSilu:
      return silu(x);
    case Act::kElu:
      return elu(x);
    case Act::kRelu:
      return relu(x);
    case Act::kTanh:
      return tanh(x);
    case Act::kSigmoid:
      return sigmoid(x);
  }
  return x;
}

void init_trunc_normal(Parameter& p, std::int64_t fan_in, std::int64_t fan_out, float scale,
                       Rng& rng) {
  // Std of a unit normal truncated to [-2, 2]; dividing by it restores the intended variance.
  constexpr double kTruncStd = 0.87962566103423978;
  const double fan_avg = 0.5 * static_cast<double>(fan_in + fan_out);
  const float std = static_cast<float>(std::sqrt(scale / fan_avg) / kTruncStd);
  for (float& v : p.value()) {
    float z;
    do {
      z = rng.normal();
    } while (z < -2.0f || z > 2.0f);
    v = z * std;
  }
}

// ---- Linear ----

Linear::Linear(ParamGroup& group, const std::string& name, int in, int out, LinearOptions options,
               Rng& rng)
    : in_(in), out_(out), one_hot_from_(options.one_hot_from) {
  INDRIVE_CHECK(one_hot_from_ <= in)
      << name << ": one-hot columns from " << one_hot_from_ << " of an input with " << in;
  w_ = &group.add(name + ".w", Shape{in, out});
  if (options.init == Init::kTruncNormal) init_trunc_normal(*w_, in, out, options.scale, rng);
  if (options.bias) b_ = &group.add(name + ".b", Shape{out});
}

Tensor Linear::operator()(Tensor x) const {
  INDRIVE_CHECK(w_ != nullptr) << "Linear used before construction";
  const Tensor b = b_ ? b_->tensor() : Tensor();
  if (one_hot_from_ >= 0) return linear_one_hot_tail(x, w_->tensor(), b, one_hot_from_);
  return linear(x, w_->tensor(), b);
}

Tensor Linear::weight() const {
  INDRIVE_CHECK(w_ != nullptr) << "Linear used before construction";
  return w_->tensor();
}

Tensor Linear::bias() const { return b_ ? b_->tensor() : Tensor(); }

// ---- LayerNorm ----

LayerNorm::LayerNorm(ParamGroup& group, const std::string& name, int dim, float eps) : eps_(eps) {
  scale_ = &group.add(name + ".scale", Shape{dim});
  offset_ = &group.add(name + ".offset", Shape{dim});
  for (float& v : scale_->value()) v = 1.0f;
}

Tensor LayerNorm::operator()(Tensor x) const {
  return layer_norm(x, scale_->tensor(), offset_->tensor(), eps_);
}

Tensor LayerNorm::operator()(Tensor x, Act act) const {
  if (act == Act::kSilu) return layer_norm_silu(x, scale_->tensor(), offset_->tensor(), eps_);
  return activate((*this)(x), act);
}

// ---- MLP ----

Mlp::Mlp(ParamGroup& group, const std::string& name, int in, MlpOptions options, Rng& rng)
    : options_(options), in_(in) {
  int dim = in;
  for (int i = 0; i < options.layers; ++i) {
    const std::string layer = name + ".h" + std::to_string(i);
    hidden_.emplace_back(
        group, layer, dim, options.units,
        LinearOptions{.bias = !options.norm, .one_hot_from = i == 0 ? options.one_hot_from : -1},
        rng);
    if (options.norm) norms_.emplace_back(group, layer + ".norm", options.units);
    dim = options.units;
  }
  if (options.out > 0)
    out_ = Linear(group, name + ".out", dim, options.out,
                  LinearOptions{.bias = true,
                                .init = options.out_init,
                                .scale = options.out_scale,
                                .one_hot_from = options.layers == 0 ? options.one_hot_from : -1},
                  rng);
}

Tensor Mlp::operator()(Tensor x) const {
  if (hidden_.empty()) return options_.out > 0 ? out_(x) : x;
  return after_first(hidden_[0](x));
}

Tensor Mlp::first_weight() const {
  INDRIVE_CHECK(!hidden_.empty()) << "an MLP without hidden layers has no first product";
  return hidden_[0].weight();
}

Tensor Mlp::first_bias() const {
  INDRIVE_CHECK(!hidden_.empty()) << "an MLP without hidden layers has no first product";
  return hidden_[0].bias();
}

Tensor Mlp::after_first(Tensor x) const {
  INDRIVE_CHECK(!hidden_.empty()) << "an MLP without hidden layers has no first product";
  for (std::size_t i = 0; i < hidden_.size(); ++i) {
    if (i > 0) x = hidden_[i](x);
    x = options_.norm ? norms_[i](x, options_.act) : activate(x, options_.act);
  }
  if (options_.out > 0) x = out_(x);
  return x;
}

int Mlp::out_dim() const {
  if (options_.out > 0) return options_.out;
  return options_.layers > 0 ? options_.units : in_;
}

// ---- GRU ----

GruCell::GruCell(ParamGroup& group, const std::string& name, int in, int deter, Rng& rng)
    : in_(in),
      deter_(deter),
      linear_(group, name, in + deter, 3 * deter, LinearOptions{.bias = false}, rng),
      norm_(group, name + ".norm", 3 * deter) {}

Tensor GruCell::operator()(Tensor x, Tensor h) const {
  INDRIVE_CHECK_EQ(x.cols(), in_) << "GRU input";
  INDRIVE_CHECK_EQ(h.cols(), deter_) << "GRU state";
  Tensor parts = norm_(linear_(concat({x, h}, -1)));
  Tensor reset = sigmoid(slice(parts, 0, deter_));
  Tensor cand = tanh(mul(reset, slice(parts, deter_, 2 * deter_)));
  Tensor update = sigmoid(add_scalar(slice(parts, 2 * deter_, 3 * deter_), -1.0f));
  // h' = update * cand + (1 - update) * h = h + update * (cand - h).
  return add(h, mul(update, sub(cand, h)));
}

// ---- Conv stacks ----

namespace {
int num_stages(const ConvStackOptions& o) {
  INDRIVE_CHECK(o.image >= o.min_res && o.min_res > 0) << "conv stack resolution";
  int stages = 0;
  for (int r = o.image; r > o.min_res; r /= 2) {
    INDRIVE_CHECK(r % 2 == 0) << "image size " << o.image << " must halve down to " << o.min_res;
    ++stages;
  }
  return stages;
}
}  // namespace

ConvEncoder::ConvEncoder(ParamGroup& group, const std::string& name, ConvStackOptions options,
                         Rng& rng)
    : options_(options) {
  const int stages = num_stages(options);
  int in = options.channels, out = options.depth;
  for (int i = 0; i < stages; ++i) {
    const std::string layer = name + ".conv" + std::to_string(i);
    Parameter& w = group.add(layer + ".w", Shape{16 * in, out});
    init_trunc_normal(w, 16 * in, 16 * out, 1.0f, rng);
    weights_.push_back(&w);
    norms_.emplace_back(group, layer + ".norm", out);
    in = out;
    out *= 2;
  }
  top_channels_ = in;
}

Tensor ConvEncoder::operator()(Tensor images) const {
  Tensor x = images;
  for (std::size_t i = 0; i < weights_.size(); ++i)
    x = norms_[i](conv2d(x, weights_[i]->tensor()), options_.act);
  return reshape(x, Shape{x.dim(0), x.numel() / x.dim(0)});
}

int ConvEncoder::embed_dim() const { return options_.min_res * options_.min_res * top_channels_; }

ConvDecoder::ConvDecoder(ParamGroup& group, const std::string& name, int in,
                         ConvStackOptions options, Rng& rng)
    : options_(options) {
  const int stages = num_stages(options);
  top_channels_ = options.depth << (stages - 1);
  in_ = Linear(group, name + ".in", in, options.min_res * options.min_res * top_channels_,
               LinearOptions{.one_hot_from = options.one_hot_from}, rng);
  int c = top_channels_;
  for (int i = 0; i < stages; ++i) {
    const bool last = i == stages - 1;
    const int out = last ? options.channels : c / 2;
    const std::string layer = name + ".deconv" + std::to_string(i);
    Parameter& w = group.add(layer + ".w", Shape{c, 16 * out});
    init_trunc_normal(w, 16 * c, 16 * out, 1.0f, rng);
    weights_.push_back(&w);
    if (last)
      out_bias_ = &group.add(layer + ".b", Shape{out});
    else
      norms_.emplace_back(group, layer + ".norm", out);
    c = out;
  }
}

Tensor ConvDecoder::operator()(Tensor features) const {
  Tensor x = in_(features);
  x = reshape(x, Shape{x.dim(0), options_.min_res, options_.min_res, top_channels_});
  for (std::size_t i = 0; i < weights_.size(); ++i) {
    if (i + 1 == weights_.size()) {
      x = conv_transpose2d(x, weights_[i]->tensor(), out_bias_->tensor());
    } else {
      x = norms_[i](conv_transpose2d(x, weights_[i]->tensor()), options_.act);
    }
  }
  return x;
}

}  // namespace indrive::nn
