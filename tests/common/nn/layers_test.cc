// Layers: initialisation, gradient checks of every layer and of composites (GRU unroll with
// straight-through sampling, conv encoder + decoder, two-hot head), learning tests, and
// bitwise reproducibility.
#include "indrive/nn/layers.h"

#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <cstring>
#include <iostream>

#include "grad_check.h"
#include "indrive/nn/nn.h"

namespace indrive::nn {
namespace {

using testing::check_gradients;
using testing::fill_uniform;

class LayersTest : public ::testing::Test {
 protected:
  void SetUp() override { current_graph().reset(); }
  Parameter& input(const std::string& name, const Shape& shape) {
    Parameter& p = in_.add(name, shape);
    fill_uniform(p, rng_);
    return p;
  }
  // Gives every parameter of the model non-trivial values (norm scales near 1), so that the
  // gradient check exercises every path.
  void randomize(ParamGroup& g, float spread = 0.3f) {
    for (const auto& p : g.params())
      for (float& v : p->value()) v += spread * (2.0f * rng_.uniform() - 1.0f);
  }
  ParamGroup in_{"in"};
  ParamGroup model_{"model"};
  Rng rng_{77};
};

TEST_F(LayersTest, TruncatedNormalInitHasFanAverageStd) {
  Linear layer(model_, "l", 300, 500, {}, rng_);
  const Parameter& w = *model_.find("l.w");
  const double expect_std = std::sqrt(1.0 / 400.0);
  double var = 0, mean = 0;
  float max_abs = 0;
  for (float v : w.value()) {
    mean += v / w.numel();
    var += double(v) * v / w.numel();
    max_abs = std::max(max_abs, std::fabs(v));
  }
  EXPECT_NEAR(mean, 0.0, 0.01 * expect_std);
  EXPECT_NEAR(std::sqrt(var), expect_std, 0.02 * expect_std);
  EXPECT_LE(max_abs, 2.0 * expect_std / 0.8796 + 1e-6);  // truncated at two raw stds
  for (float v : model_.find("l.b")->value()) EXPECT_EQ(v, 0.0f);
  Mlp head(model_, "head", 8, {.units = 16, .layers = 1, .out = 255, .out_init = Init::kZeros},
           rng_);
  for (float v : model_.find("head.out.w")->value()) EXPECT_EQ(v, 0.0f);
  // Layers followed by a norm have no bias.
  EXPECT_EQ(model_.find("head.h0.b"), nullptr);
  EXPECT_NE(model_.find("head.h0.norm.scale"), nullptr);
}

TEST_F(LayersTest, LinearNormAndMlpGradients) {
  Parameter& x = input("x", {4, 6});
  Linear linear(model_, "lin", 6, 5, {}, rng_);
  LayerNorm norm(model_, "norm", 5);
  Mlp mlp(model_, "mlp", 6, {.units = 8, .layers = 2, .act = Act::kSilu, .out = 3}, rng_);
  Mlp elu_mlp(model_, "elu", 6, {.units = 7, .layers = 1, .norm = false, .act = Act::kElu}, rng_);
  randomize(model_);
  EXPECT_EQ(
      check_gradients("linear+norm", [&] { return norm(linear(x.tensor())); }, {&in_, &model_}), 0);
  EXPECT_EQ(check_gradients("mlp", [&] { return mlp(x.tensor()); }, {&in_, &model_}), 0);
  EXPECT_EQ(check_gradients("mlp elu", [&] { return elu_mlp(x.tensor()); }, {&in_, &model_}), 0);
}

TEST_F(LayersTest, GruCellMatchesItsFormulaAndGradients) {
  Parameter& x = input("x", {3, 5});
  Parameter& h = input("h", {3, 4});
  GruCell gru(model_, "gru", 5, 4, rng_);
  randomize(model_);
  EXPECT_EQ(check_gradients("gru", [&] { return gru(x.tensor(), h.tensor()); }, {&in_, &model_}),
            0);
  // Value check against the formula written out with plain loops.
  Tensor out = gru(x.tensor(), h.tensor());
  const Parameter& w = *model_.find("gru.w");
  const Parameter& sc = *model_.find("gru.norm.scale");
  const Parameter& of = *model_.find("gru.norm.offset");
  for (int b = 0; b < 3; ++b) {
    std::vector<double> in(9), lin(12);
    for (int i = 0; i < 5; ++i) in[i] = x.value()[b * 5 + i];
    for (int i = 0; i < 4; ++i) in[5 + i] = h.value()[b * 4 + i];
    for (int o = 0; o < 12; ++o)
      for (int i = 0; i < 9; ++i) lin[o] += in[i] * w.value()[i * 12 + o];
    double mu = 0, var = 0;
    for (double v : lin) mu += v / 12;
    for (double v : lin) var += (v - mu) * (v - mu) / 12;
    for (int o = 0; o < 12; ++o)
      lin[o] = (lin[o] - mu) / std::sqrt(var + 1e-3) * sc.value()[o] + of.value()[o];
    for (int d = 0; d < 4; ++d) {
      const double reset = 1 / (1 + std::exp(-lin[d]));
      const double cand = std::tanh(reset * lin[4 + d]);
      const double update = 1 / (1 + std::exp(-(lin[8 + d] - 1)));
      const double expect = update * cand + (1 - update) * h.value()[b * 4 + d];
      EXPECT_NEAR(out.data()[b * 4 + d], expect, 1e-5);
    }
  }
}

TEST_F(LayersTest, GruUnrollWithStraightThroughSamplesGradients) {
  // Three RSSM-like steps: z_t = sample(unimix(head(h_t))), h_{t+1} = gru([z_t, a_t], h_t).
  // The sampler is reseeded per evaluation, so the finite differences see the same samples
  // (frozen), while the straight-through gradient flows through the probabilities.
  constexpr int kGroups = 2, kClasses = 3, kDeter = 6, kBatch = 2, kSteps = 3;
  Parameter& actions = input("actions", {kSteps, kBatch, 2});
  Parameter& h0 = input("h0", {kBatch, kDeter});
  GruCell gru(model_, "gru", kGroups * kClasses + 2, kDeter, rng_);
  Linear head(model_, "head", kDeter, kGroups * kClasses, {}, rng_);
  randomize(model_);
  // The first call (the analytic pass) samples with sample_straight_through and records
  // sample - probs per step; the finite-difference passes use frozen + probs, whose true
  // derivative is the straight-through gradient, so the two passes must agree.
  std::vector<std::vector<float>> frozen;
  auto unroll = [&] {
    Rng sampler(11);
    const bool analytic = frozen.size() < kSteps;
    Tensor h = h0.tensor();
    Tensor z = zeros({kBatch, kGroups * kClasses});
    std::vector<Tensor> outputs;
    for (int t = 0; t < kSteps; ++t) {
      Tensor a = reshape(slice(actions.tensor(), t, t + 1, 0), Shape{kBatch, 2});
      h = gru(concat({z, a}), h);
      Tensor probs = unimix_probs(head(h), kClasses);
      if (analytic) {
        z = sample_straight_through(probs, kClasses, sampler);
        std::vector<float> offset(static_cast<std::size_t>(z.numel()));
        for (std::size_t i = 0; i < offset.size(); ++i) offset[i] = z.data()[i] - probs.data()[i];
        frozen.push_back(offset);
      } else {
        z = add(constant(probs.shape(), frozen[t]), probs);
      }
      outputs.push_back(concat({h, z, probs}));
    }
    return concat(outputs, 0);
  };
  EXPECT_EQ(check_gradients("gru unroll", unroll, {&in_, &model_}), 0);
}

TEST_F(LayersTest, ConvEncoderDecoderGradients) {
  const ConvStackOptions options{.image = 8, .channels = 3, .depth = 4, .min_res = 2};
  Parameter& images = input("images", {2, 8, 8, 3});
  ConvEncoder encoder(model_, "enc", options, rng_);
  ConvDecoder decoder(model_, "dec", encoder.embed_dim(), options, rng_);
  randomize(model_, 0.2f);
  EXPECT_EQ(encoder.embed_dim(), 2 * 2 * 8);
  Tensor probe = decoder(encoder(images.tensor()));
  EXPECT_EQ(probe.shape(), (Shape{2, 8, 8, 3}));
  EXPECT_EQ(check_gradients("conv autoencoder", [&] { return decoder(encoder(images.tensor())); },
                            {&in_, &model_}, {.step = 2e-3f, .atol = 3e-3f, .rtol = 3e-2f}),
            0);
}

TEST_F(LayersTest, TwoHotHeadGradients) {
  Parameter& x = input("x", {3, 4});
  Mlp head(model_, "reward", 4, {.units = 8, .layers = 1, .out = kTwoHotBins}, rng_);
  randomize(model_, 0.1f);
  const std::vector<float> targets = {1.5f, -30.0f, 0.0f};
  EXPECT_EQ(check_gradients(
                "two-hot head",
                [&] { return twohot_cross_entropy(head(x.tensor()), constant({3}, targets)); },
                {&in_, &model_}),
            0);
}

// Fits y = sin(2 x0) * cos(x1) + 0.5 x2^2 on [-1.5, 1.5]^3.
double fit_regression(std::uint64_t seed, ParamGroup& model, int steps) {
  Rng rng(seed);
  // No LayerNorm here: normalising a projection of only 3 inputs discards their magnitude.
  Mlp net(model, "net", 3, {.units = 64, .layers = 2, .norm = false, .out = 1}, rng);
  Adam adam(model, {.lr = 3e-3f});
  std::vector<float> xs(64 * 3), ys(64);
  double loss = 0;
  for (int step = 0; step < steps; ++step) {
    for (int i = 0; i < 64; ++i) {
      for (int j = 0; j < 3; ++j) xs[i * 3 + j] = 3.0f * rng.uniform() - 1.5f;
      ys[i] =
          std::sin(2 * xs[i * 3]) * std::cos(xs[i * 3 + 1]) + 0.5f * xs[i * 3 + 2] * xs[i * 3 + 2];
    }
    Graph& g = current_graph();
    g.reset();
    Tensor l = mse(net(constant({64, 3}, xs)), constant({64, 1}, ys));
    loss = 0.98 * loss + 0.02 * l.item();  // smoothed over ~50 batches
    if (step == 0) loss = l.item();
    g.backward(l);
    adam.step();
  }
  return loss;
}

TEST_F(LayersTest, MlpLearnsNonlinearRegression) {
  // The target's variance is about 0.36; predicting the mean gives MSE ~0.36.
  const auto start = std::chrono::steady_clock::now();
  const double loss = fit_regression(3, model_, 2000);
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  EXPECT_LT(loss, 0.01) << "smoothed MSE after 2000 steps";
  std::cout << "regression: smoothed MSE " << loss << " in " << seconds << " s\n";
}

TEST_F(LayersTest, TrainingIsBitwiseReproducibleWithOneThread) {
  const int saved = threads();
  set_threads(1);
  ParamGroup a("model"), b("model");
  fit_regression(5, a, 50);
  fit_regression(5, b, 50);
  set_threads(saved);
  for (std::size_t i = 0; i < a.params().size(); ++i) {
    const auto va = a.params()[i]->value();
    const auto vb = b.params()[i]->value();
    ASSERT_EQ(va.size(), vb.size());
    EXPECT_EQ(std::memcmp(va.data(), vb.data(), va.size() * sizeof(float)), 0)
        << a.params()[i]->name();
  }
}

TEST_F(LayersTest, ConvAutoencoderReconstructsSyntheticImages) {
  // 16x16 images of one bright axis-aligned square on a dark background at a random place.
  constexpr int kImage = 16, kBatch = 32;
  const ConvStackOptions options{.image = kImage, .channels = 3, .depth = 8, .min_res = 4};
  ConvEncoder encoder(model_, "enc", options, rng_);
  ConvDecoder decoder(model_, "dec", encoder.embed_dim(), options, rng_);
  Adam adam(model_, {.lr = 2e-3f});
  Rng data(9);
  std::vector<float> pixels(kBatch * kImage * kImage * 3);
  auto make_batch = [&] {
    std::fill(pixels.begin(), pixels.end(), 0.1f);
    for (int b = 0; b < kBatch; ++b) {
      const int size = 4 + static_cast<int>(data.below(4));
      const int y0 = static_cast<int>(data.below(kImage - size)),
                x0 = static_cast<int>(data.below(kImage - size));
      const int channel = static_cast<int>(data.below(3));
      for (int y = y0; y < y0 + size; ++y)
        for (int x = x0; x < x0 + size; ++x)
          pixels[((b * kImage + y) * kImage + x) * 3 + channel] = 0.9f;
    }
  };
  // Baseline: the error of always predicting the mean image of the data.
  std::vector<double> mean_image(pixels.size() / kBatch, 0.0);
  for (int i = 0; i < 50; ++i) {
    make_batch();
    for (std::size_t j = 0; j < pixels.size(); ++j)
      mean_image[j % mean_image.size()] += pixels[j] / (50.0 * kBatch);
  }
  double baseline = 0;
  for (int i = 0; i < 50; ++i) {
    make_batch();
    for (std::size_t j = 0; j < pixels.size(); ++j)
      baseline +=
          std::pow(pixels[j] - mean_image[j % mean_image.size()], 2) / (50.0 * pixels.size());
  }
  double first = 0, last = 0;
  const auto start = std::chrono::steady_clock::now();
  for (int step = 0; step < 400; ++step) {
    make_batch();
    Graph& g = current_graph();
    g.reset();
    Tensor target = constant({kBatch, kImage, kImage, 3}, pixels);
    Tensor recon = add_scalar(decoder(encoder(add_scalar(target, -0.5f))), 0.5f);
    Tensor loss = mse(recon, target);
    if (step < 10) first += loss.item() / 10;
    if (step >= 390) last += loss.item() / 10;
    g.backward(loss);
    adam.step();
  }
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::cout << "autoencoder: MSE " << first << " -> " << last << " (mean-image baseline "
            << baseline << ") in " << seconds << " s\n";
  // It must beat the mean image clearly, i.e. it encodes where the square is and its colour.
  EXPECT_LT(last, 0.4 * baseline);
  EXPECT_LT(last, 0.1 * first);
}

}  // namespace
}  // namespace indrive::nn
