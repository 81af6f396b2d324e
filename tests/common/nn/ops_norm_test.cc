// Tests of ops_norm.cc: LayerNorm (with SiLU), softmax and log-softmax at every kernel width, and
// their thread-count invariance.
#include "ops_test_support.h"

namespace indrive::nn {
namespace {

TEST_F(OpsTest, LayerNormGradientsAndValues) {
  Parameter& x = input("x", {4, 8}, -2.0f, 2.0f);
  Parameter& g = input("g", {8}, 0.5f, 1.5f);
  Parameter& b = input("b", {8});
  EXPECT_EQ(
      check("layer_norm", [&] { return layer_norm(x.tensor(), g.tensor(), b.tensor(), 1e-3f); }),
      0);
  EXPECT_EQ(check("layer_norm plain", [&] { return layer_norm(x.tensor(), {}, {}, 1e-3f); }), 0);
  EXPECT_EQ(check("layer_norm_silu",
                  [&] { return layer_norm_silu(x.tensor(), g.tensor(), b.tensor(), 1e-3f); }),
            0);
  Tensor fused = layer_norm_silu(x.tensor(), g.tensor(), b.tensor(), 1e-3f);
  Tensor plain = silu(layer_norm(x.tensor(), g.tensor(), b.tensor(), 1e-3f));
  for (int i = 0; i < 32; ++i) EXPECT_NEAR(fused.data()[i], plain.data()[i], 1e-6f);
  Tensor y = layer_norm(x.tensor(), {}, {}, 1e-3f);
  for (int r = 0; r < 4; ++r) {
    double m = 0, v = 0, xm = 0, xv = 0;
    for (int c = 0; c < 8; ++c) xm += x.value()[r * 8 + c] / 8.0;
    for (int c = 0; c < 8; ++c) xv += std::pow(x.value()[r * 8 + c] - xm, 2) / 8.0;
    for (int c = 0; c < 8; ++c) m += y.data()[r * 8 + c] / 8.0;
    for (int c = 0; c < 8; ++c) v += std::pow(y.data()[r * 8 + c] - m, 2) / 8.0;
    EXPECT_NEAR(m, 0.0, 1e-5);
    EXPECT_NEAR(v, xv / (xv + 1e-3), 1e-4);  // eps 1e-3 shrinks the variance slightly
  }
}

// The widths with their own fixed-size kernel (8, 16, 32) and others, with and without SiLU,
// against the formula in double.
TEST_F(OpsTest, LayerNormEveryWidthMatchesTheFormula) {
  for (int cols : {5, 8, 16, 24, 32, 128}) {
    const std::string w = std::to_string(cols);
    Parameter& x = input("x" + w, {7, cols}, -2.0f, 2.0f);
    Parameter& g = input("g" + w, {cols}, 0.5f, 1.5f);
    Parameter& b = input("b" + w, {cols});
    for (bool with_silu : {false, true}) {
      Tensor y = with_silu ? layer_norm_silu(x.tensor(), g.tensor(), b.tensor(), 1e-3f)
                           : layer_norm(x.tensor(), g.tensor(), b.tensor(), 1e-3f);
      for (int r = 0; r < 7; ++r) {
        double mu = 0, var = 0;
        for (int c = 0; c < cols; ++c) mu += x.value()[r * cols + c] / cols;
        for (int c = 0; c < cols; ++c) var += std::pow(x.value()[r * cols + c] - mu, 2) / cols;
        for (int c = 0; c < cols; ++c) {
          double v =
              (x.value()[r * cols + c] - mu) / std::sqrt(var + 1e-3) * g.value()[c] + b.value()[c];
          if (with_silu) v = v / (1 + std::exp(-v));
          EXPECT_NEAR(y.data()[r * cols + c], v, 1e-5) << "width " << cols << " row " << r;
        }
      }
    }
  }
}

// The backward rule at the widths with their own fixed-size kernel (8, 16, 32) and others, with
// and without scale and offset, with SiLU, and adding to a gradient another use of x left.
TEST_F(OpsTest, LayerNormGradientsAtEveryWidth) {
  for (int cols : {5, 8, 16, 32, 40}) {
    const std::string w = std::to_string(cols);
    Parameter& x = input("x" + w, {3, cols}, -2.0f, 2.0f);
    Parameter& g = input("g" + w, {cols}, 0.5f, 1.5f);
    Parameter& b = input("b" + w, {cols});
    EXPECT_EQ(check("layer_norm " + w,
                    [&] { return layer_norm(x.tensor(), g.tensor(), b.tensor(), 1e-3f); }),
              0);
    EXPECT_EQ(check("layer_norm plain " + w, [&] { return layer_norm(x.tensor(), {}, {}, 1e-3f); }),
              0);
    EXPECT_EQ(check("layer_norm_silu " + w,
                    [&] { return layer_norm_silu(x.tensor(), g.tensor(), b.tensor(), 1e-3f); }),
              0);
    EXPECT_EQ(check("layer_norm_silu + x " + w,
                    [&] {
                      return add(layer_norm_silu(x.tensor(), g.tensor(), b.tensor(), 1e-3f),
                                 scale(x.tensor(), 0.5f));
                    }),
              0);
  }
}

TEST_F(OpsTest, LayerNormLargeInputsSplitIntoChunksMatchRowByRow) {
  // Enough rows for the chunked (and possibly parallel) path; compare against small calls.
  Parameter& x = input("x", {3000, 24}, -2.0f, 2.0f);
  Parameter& g = input("g", {24}, 0.5f, 1.5f);
  Parameter& b = input("b", {24});
  Tensor big = layer_norm_silu(x.tensor(), g.tensor(), b.tensor());
  for (int r : {0, 511, 512, 2999}) {
    Tensor row = layer_norm_silu(slice(x.tensor(), r, r + 1, 0), g.tensor(), b.tensor());
    for (int c = 0; c < 24; ++c) EXPECT_FLOAT_EQ(big.data()[r * 24 + c], row.data()[c]);
  }
  // Scale gradient summed over chunks equals the sum of per-row contributions.
  current_graph().backward(sum(big));
  const float total = g.grad()[5];
  in_.zero_grad();
  double expect = 0;
  for (int r = 0; r < 3000; r += 1) {
    current_graph().reset();
    Tensor row = layer_norm_silu(slice(x.tensor(), r, r + 1, 0), g.tensor(), b.tensor());
    current_graph().backward(sum(row));
    expect += g.grad()[5];
    in_.zero_grad();
  }
  EXPECT_NEAR(total, expect, 1e-3 * std::fabs(expect) + 1e-3);
}

// The row ops (LayerNorm with SiLU, softmax, log-softmax, a row sum and its backward) on inputs
// large enough to be split over threads give the same bits with 1 and 2 threads.
TEST_F(OpsTest, RowOpsGiveTheSameBitsWithOneAndTwoThreads) {
  Parameter& x = input("x", {2048, 96}, -3.0f, 3.0f);
  Parameter& g = input("g", {96}, 0.5f, 1.5f);
  Parameter& b = input("b", {96});
  auto run = [&](int threads) {
    const int saved = nn::threads();
    set_threads(threads);
    current_graph().reset();
    in_.zero_grad();
    Tensor y = layer_norm_silu(x.tensor(), g.tensor(), b.tensor());
    Tensor s = softmax(reshape(y, Shape{2048 * 6, 16}));
    Tensor l = log_softmax(y);
    Tensor loss = add(sum(mul(s, s)), mean(sum(l, -1)));
    current_graph().backward(loss);
    std::vector<float> out(s.data(), s.data() + s.numel());
    out.insert(out.end(), l.data(), l.data() + l.numel());
    for (Parameter* p : {&x, &g, &b}) out.insert(out.end(), p->grad().begin(), p->grad().end());
    set_threads(saved);
    return out;
  };
  const std::vector<float> one = run(1), two = run(2);
  ASSERT_EQ(one.size(), two.size());
  EXPECT_EQ(std::memcmp(one.data(), two.data(), one.size() * sizeof(float)), 0);
}

TEST_F(OpsTest, SoftmaxGradientsAndValues) {
  Parameter& x = input("x", {3, 2, 5}, -3.0f, 3.0f);
  EXPECT_EQ(check("softmax", [&] { return softmax(x.tensor()); }), 0);
  EXPECT_EQ(check("log_softmax", [&] { return log_softmax(x.tensor()); }), 0);
  Tensor p = softmax(x.tensor());
  Tensor lp = log_softmax(x.tensor());
  for (int r = 0; r < 6; ++r) {
    float total = 0;
    for (int c = 0; c < 5; ++c) {
      total += p.data()[r * 5 + c];
      EXPECT_NEAR(std::log(p.data()[r * 5 + c]), lp.data()[r * 5 + c], 1e-5f);
    }
    EXPECT_NEAR(total, 1.0f, 1e-6f);
  }
  // Large logits stay finite.
  Tensor big = log_softmax(constant({1, 2}, std::vector<float>{1000.0f, 0.0f}));
  EXPECT_NEAR(big.data()[0], 0.0f, 1e-6f);
  EXPECT_NEAR(big.data()[1], -1000.0f, 1e-3f);
}

// The backward rules of softmax and log-softmax at the widths with their own fixed-size kernel
// (16, 32) and another, both when the input's gradient is written fresh and when it adds to a
// gradient that another use of the input already left there.
TEST_F(OpsTest, SoftmaxGradientsAtEveryWidthFreshAndAccumulated) {
  for (int cols : {9, 16, 32}) {
    std::string name = "x";
    name += std::to_string(cols);
    Parameter& x = input(name, {4, cols}, -3.0f, 3.0f);
    EXPECT_EQ(check("softmax", [&] { return softmax(x.tensor()); }), 0) << "width " << cols;
    EXPECT_EQ(check("log_softmax", [&] { return log_softmax(x.tensor()); }), 0) << "width " << cols;
    EXPECT_EQ(
        check("softmax + x", [&] { return add(softmax(x.tensor()), scale(x.tensor(), 0.5f)); }), 0)
        << "width " << cols;
    EXPECT_EQ(check("log_softmax + x",
                    [&] { return add(log_softmax(x.tensor()), scale(x.tensor(), 0.5f)); }),
              0)
        << "width " << cols;
  }
}

// The widths with their own fixed-size kernel (16, 32) and others against the formula.
TEST_F(OpsTest, SoftmaxEveryWidthMatchesTheFormula) {
  for (int cols : {9, 16, 32, 255}) {
    std::string name = "x";  // appended: GCC 12 warns (-Wrestrict, a false positive) on "x" + s
    name += std::to_string(cols);
    Parameter& x = input(name, {5, cols}, -4.0f, 4.0f);
    Tensor p = softmax(x.tensor());
    Tensor lp = log_softmax(x.tensor());
    for (int r = 0; r < 5; ++r) {
      double total = 0;
      for (int c = 0; c < cols; ++c) total += std::exp(x.value()[r * cols + c]);
      for (int c = 0; c < cols; ++c) {
        const double logp = x.value()[r * cols + c] - std::log(total);
        EXPECT_NEAR(p.data()[r * cols + c], std::exp(logp), 1e-6) << "width " << cols;
        EXPECT_NEAR(lp.data()[r * cols + c], logp, 1e-5) << "width " << cols;
      }
    }
  }
}

}  // namespace
}  // namespace indrive::nn
