// Layers built from ops: Linear, LayerNorm, MLP, DreamerV3's GRU cell, and conv encoder/decoder
// stacks. A layer registers its parameters in a ParamGroup under a name prefix at construction
// and initialises them as DreamerV3 does (truncated normal scaled by fan-average).
#pragma once

#include <string>
#include <vector>

#include "indrive/nn/ops.h"
#include "indrive/nn/tensor.h"

namespace indrive::nn {

// Activation applied after a layer.
enum class Act { kNone, kSilu, kElu, kRelu, kTanh, kSigmoid };

// Applies `act` to x (kNone returns x).
Tensor activate(Tensor x, Act act);

// How a layer's weights are initialised.
enum class Init {
  kTruncNormal,  // truncated normal, std = scale * sqrt(1 / fan_avg) / 0.8796 (DreamerV3)
  kZeros,        // zeros: output layers of reward and critic heads
};

// Fills `p` with a truncated normal (cut at 2 std) of std sqrt(scale / ((fan_in + fan_out) / 2))
// corrected for the truncation, as DreamerV3's "trunc_normal" initialiser with fan_avg.
void init_trunc_normal(Parameter& p, std::int64_t fan_in, std::int64_t fan_out, float scale,
                       Rng& rng);

// Options of a Linear layer.
struct LinearOptions {
  bool bias = true;  // DreamerV3 drops the bias when a norm follows
  Init init = Init::kTruncNormal;
  float scale = 1.0f;
  // The input's columns from this one on hold one-hot blocks (a model state's stochastic part,
  // an action): the layer gathers their rows of w instead of multiplying
  // (linear_one_hot_tail). -1: a dense input.
  int one_hot_from = -1;
};

// y = x * w + b. w is (in, out), b is (out).
class Linear {
 public:
  Linear() = default;
  // Registers "<name>.w" (and "<name>.b") in `group`.
  Linear(ParamGroup& group, const std::string& name, int in, int out, LinearOptions options,
         Rng& rng);
  // x is (..., in); result is (..., out).
  Tensor operator()(Tensor x) const;
  int in() const { return in_; }
  int out() const { return out_; }
  Tensor weight() const;
  Tensor bias() const;  // undefined without a bias

 private:
  int in_ = 0, out_ = 0;
  int one_hot_from_ = -1;
  Parameter* w_ = nullptr;
  Parameter* b_ = nullptr;
};

// LayerNorm over the last axis with a learned scale (ones) and offset (zeros), eps 1e-3.
class LayerNorm {
 public:
  LayerNorm() = default;
  // Registers "<name>.scale" and "<name>.offset" of size `dim`.
  LayerNorm(ParamGroup& group, const std::string& name, int dim, float eps = 1e-3f);
  // x is (..., dim); result has the same shape.
  Tensor operator()(Tensor x) const;
  // activate(norm(x), act), fused into one op for SiLU.
  Tensor operator()(Tensor x, Act act) const;

 private:
  Parameter* scale_ = nullptr;
  Parameter* offset_ = nullptr;
  float eps_ = 1e-3f;
};

// Options of an MLP: `layers` hidden layers of `units`, each Linear (no bias when normed) ->
// LayerNorm -> activation, then an optional output Linear of size `out`.
struct MlpOptions {
  int units = 256;
  int layers = 2;
  bool norm = true;
  Act act = Act::kSilu;
  int out = 0;                         // 0: no output layer; the result is the last hidden layer
  Init out_init = Init::kTruncNormal;  // kZeros for reward and critic heads
  float out_scale = 1.0f;
  int one_hot_from = -1;  // the first layer's LinearOptions::one_hot_from
};

// Multi-layer perceptron as in DreamerV3.
class Mlp {
 public:
  Mlp() = default;
  // Registers "<name>.h<i>.*" and "<name>.out.*" in `group`.
  Mlp(ParamGroup& group, const std::string& name, int in, MlpOptions options, Rng& rng);
  // x is (..., in); result is (..., out_dim()).
  Tensor operator()(Tensor x) const;
  int out_dim() const;

  // The MLP split after its first product, so that several MLPs reading the same input can
  // make their first products as one GEMM (a Linear of the weights side by side, see
  // LatentDisagreement): first_weight() is the first hidden layer's (in, units) weight and
  // first_bias() its bias (undefined without one); after_first(x @ first_weight() + bias) is
  // operator()(x). Needs at least one hidden layer.
  Tensor first_weight() const;
  Tensor first_bias() const;
  Tensor after_first(Tensor first_product) const;

 private:
  MlpOptions options_;
  int in_ = 0;
  std::vector<Linear> hidden_;
  std::vector<LayerNorm> norms_;
  Linear out_;
};

// DreamerV3's GRU cell: one bias-free Linear over [x, h] to 3 * deter, LayerNorm, split into
// reset, candidate, update; reset = sigmoid(reset); cand = tanh(reset * cand);
// update = sigmoid(update - 1); h' = update * cand + (1 - update) * h.
class GruCell {
 public:
  GruCell() = default;
  // Registers "<name>.w" and "<name>.norm.*" in `group`.
  GruCell(ParamGroup& group, const std::string& name, int in, int deter, Rng& rng);
  // x is (B, in), h is (B, deter); result is the new state (B, deter).
  Tensor operator()(Tensor x, Tensor h) const;
  int deter() const { return deter_; }

 private:
  int in_ = 0, deter_ = 0;
  Linear linear_;
  LayerNorm norm_;
};

// Options of the conv stacks: the image is halved by each kernel-4 stride-2 conv until it
// reaches `min_res`, doubling channels from `depth`; every conv is followed by a channel
// LayerNorm and the activation (the decoder's last layer has a bias and neither).
struct ConvStackOptions {
  int image = 64;    // square input/output resolution
  int channels = 3;  // image channels
  int depth = 16;    // channels of the first conv
  int min_res = 4;   // resolution of the deepest feature map
  Act act = Act::kSilu;
  int one_hot_from = -1;  // decoder: its features' one-hot columns (LinearOptions::one_hot_from)
};

// Image encoder: (N, image, image, channels) -> (N, embed_dim()).
class ConvEncoder {
 public:
  ConvEncoder() = default;
  // Registers "<name>.conv<i>.*" in `group`.
  ConvEncoder(ParamGroup& group, const std::string& name, ConvStackOptions options, Rng& rng);
  // images is (N, image, image, channels), typically in [-0.5, 0.5]; result is (N, embed).
  Tensor operator()(Tensor images) const;
  // Size of the flattened deepest feature map: min_res^2 * top channels.
  int embed_dim() const;
  int top_channels() const { return top_channels_; }

 private:
  ConvStackOptions options_;
  int top_channels_ = 0;
  std::vector<Parameter*> weights_;
  std::vector<LayerNorm> norms_;
};

// Image decoder: (N, in) -> Linear -> (N, min_res, min_res, top) -> transposed convs ->
// (N, image, image, channels), mirroring ConvEncoder.
class ConvDecoder {
 public:
  ConvDecoder() = default;
  // Registers "<name>.in.*", "<name>.deconv<i>.*" in `group`.
  ConvDecoder(ParamGroup& group, const std::string& name, int in, ConvStackOptions options,
              Rng& rng);
  // features is (N, in); result is (N, image, image, channels) (the mean, without offset).
  Tensor operator()(Tensor features) const;

 private:
  ConvStackOptions options_;
  int top_channels_ = 0;
  Linear in_;
  std::vector<Parameter*> weights_;
  std::vector<LayerNorm> norms_;
  Parameter* out_bias_ = nullptr;
};

}  // namespace indrive::nn
