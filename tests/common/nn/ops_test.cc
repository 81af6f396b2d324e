// Every op: values against direct formulas, gradients against central finite differences.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <vector>

#include "grad_check.h"
#include "indrive/nn/kernels.h"
#include "indrive/nn/nn.h"

namespace indrive::nn {
namespace {

using testing::check_gradients;
using testing::fill_uniform;
using testing::GradTolerance;

// Test inputs are parameters so that the gradient check sees them.
class OpsTest : public ::testing::Test {
 protected:
  void SetUp() override { current_graph().reset(); }
  Parameter& input(const std::string& name, const Shape& shape, float lo = -1.0f, float hi = 1.0f) {
    Parameter& p = in_.add(name, shape);
    fill_uniform(p, rng_, lo, hi);
    return p;
  }
  // Moves every value of p at least `gap` away from `kink` (keeps finite differences smooth).
  static void avoid(Parameter& p, float kink, float gap = 0.05f) {
    for (float& v : p.value())
      if (std::fabs(v - kink) < gap) v = kink + (v < kink ? -gap : gap);
  }
  int check(const std::string& what, const std::function<Tensor()>& f, GradTolerance tol = {}) {
    return check_gradients(what, f, {&in_}, tol);
  }
  ParamGroup in_{"in"};
  Rng rng_{1234};
};

TEST_F(OpsTest, MatmulAndLinearGradients) {
  Parameter& x = input("x", {5, 7});
  Parameter& w = input("w", {7, 3});
  Parameter& b = input("b", {3});
  EXPECT_EQ(check("matmul", [&] { return matmul(x.tensor(), w.tensor()); }), 0);
  EXPECT_EQ(check("linear", [&] { return linear(x.tensor(), w.tensor(), b.tensor()); }), 0);
}

TEST_F(OpsTest, MatmulValuesMatchLoops) {
  Parameter& x = input("x", {2, 3, 4});
  Parameter& w = input("w", {4, 5});
  Tensor y = matmul(x.tensor(), w.tensor());
  ASSERT_EQ(y.shape(), (Shape{2, 3, 5}));
  for (int r = 0; r < 6; ++r)
    for (int c = 0; c < 5; ++c) {
      float expect = 0;
      for (int k = 0; k < 4; ++k) expect += x.value()[r * 4 + k] * w.value()[k * 5 + c];
      EXPECT_NEAR(y.data()[r * 5 + c], expect, 1e-5f);
    }
}

// linear_one_hot_tail against linear on the same input: x is `dense` random columns, then
// `groups` one-hot blocks of `classes`, then an action block of 9 that is all zeros in every
// fifth row (no action yet). Returns the largest difference over the values and the gradients
// of x, w and b (a weighted sum of the output as the loss).
class OneHotTailTest : public OpsTest {
 protected:
  float largest_difference(std::int64_t rows, int dense, int groups, int classes, std::int64_t cols,
                           std::int64_t from) {
    const int k = dense + groups * classes + 9;
    const std::string at = std::to_string(calls_++);
    Parameter& x = input("x" + at, {rows, k});
    Parameter& w = input("w" + at, {k, cols});
    Parameter& b = input("b" + at, {cols});
    Parameter& r = input("r" + at, {rows, cols});
    std::span<float> xv = x.value();
    for (std::int64_t i = 0; i < rows; ++i) {
      float* row = xv.data() + i * k;
      std::fill(row + dense, row + k, 0.0f);
      for (int g = 0; g < groups; ++g) row[dense + g * classes + (i * 7 + g * 3) % classes] = 1.0f;
      if (i % 5 != 0) row[dense + groups * classes + i % 9] = 1.0f;
    }
    auto run = [&](bool gather) {
      current_graph().reset();
      in_.zero_grad();
      Tensor y = gather ? linear_one_hot_tail(x.tensor(), w.tensor(), b.tensor(), from)
                        : linear(x.tensor(), w.tensor(), b.tensor());
      current_graph().backward(sum(mul(y, stop_gradient(r.tensor()))));
      std::vector<float> out(y.data(), y.data() + y.numel());
      for (Parameter* p : {&x, &w, &b}) out.insert(out.end(), p->grad().begin(), p->grad().end());
      return out;
    };
    const std::vector<float> dense_run = run(false), gathered = run(true);
    EXPECT_EQ(dense_run.size(), gathered.size());
    float worst = 0;
    for (std::size_t i = 0; i < dense_run.size(); ++i)
      worst = std::max(worst, std::fabs(dense_run[i] - gathered[i]));
    return worst;
  }
  int calls_ = 0;
};

TEST_F(OneHotTailTest, GathersTheSameValuesAndGradientsAsTheProduct) {
  // A model state [deter, stoch] + action: dense part, then one-hot columns.
  EXPECT_LT(largest_difference(37, 8, 3, 8, 70, 8), 1e-4f);
  // The same with the scan that reads one column at a time (CPUs without AVX2).
  set_one_hot_scan_vectorised(false);
  EXPECT_LT(largest_difference(37, 8, 3, 8, 70, 8), 1e-4f);
  set_one_hot_scan_vectorised(true);
  // [stoch, action] (the RSSM's input): one-hot from the first column.
  EXPECT_LT(largest_difference(21, 0, 4, 4, 5, 0), 1e-4f);
  // A tail that starts inside the dense part: those columns are taken as dense (they hold
  // neither only zeros nor only ones), so the op runs the plain product.
  EXPECT_LT(largest_difference(11, 6, 2, 8, 9, 3), 1e-4f);
  // No one-hot columns at all (from = k).
  EXPECT_LT(largest_difference(9, 4, 1, 4, 6, 4 + 4 + 9), 1e-4f);
}

TEST_F(OneHotTailTest, LargeInputsSplitOverThreadsMatchTheProduct) {
  // Enough rows and columns that the gather (rows) and the weight gradient (column blocks)
  // run in parallel with two threads.
  const int saved = threads();
  set_threads(2);
  EXPECT_LT(largest_difference(700, 64, 8, 16, 200, 64), 2e-3f);
  set_threads(saved);
}

TEST_F(OneHotTailTest, ATailThatIsNotOneHotIsMultipliedNotGathered) {
  // 18 tail columns: two blocks of eight for the vector scan and two for its scalar end. A
  // probability in either part must make the product dense (a gather would read it as 0).
  Parameter& w = input("w", {20, 3});
  for (int bad_column : {5, 12, 19}) {
    Parameter& x = input("x" + std::to_string(bad_column), {4, 20});
    std::span<float> xv = x.value();
    std::fill(xv.begin(), xv.end(), 0.0f);
    for (int i = 0; i < 4; ++i) {
      xv[i * 20] = 0.25f * static_cast<float>(i + 1);  // dense columns 0-1
      xv[i * 20 + 2 + i] = 1.0f;
    }
    xv[20 + bad_column] = 0.5f;  // row 1
    const Tensor expect = linear(x.tensor(), w.tensor());
    for (bool vectorised : {true, false}) {
      set_one_hot_scan_vectorised(vectorised);
      const Tensor got = linear_one_hot_tail(x.tensor(), w.tensor(), Tensor(), 2);
      for (int i = 0; i < 12; ++i)
        EXPECT_NEAR(got.data()[i], expect.data()[i], 1e-6f) << bad_column << " " << i;
    }
    set_one_hot_scan_vectorised(true);
  }
}

TEST_F(OneHotTailTest, GradientsMatchFiniteDifferencesOfTheWeights) {
  Parameter& w = input("w", {10, 4});
  Parameter& b = input("b", {4});
  const std::vector<float> x = {0.3f,  -0.7f, 0, 1, 0, 0, 0, 1, 0, 0,  //
                                1.2f,  0.1f,  1, 0, 0, 0, 0, 0, 0, 1,  //
                                -0.4f, 0.9f,  0, 0, 1, 0, 0, 0, 0, 0};
  EXPECT_EQ(check("linear_one_hot_tail",
                  [&] {
                    return linear_one_hot_tail(constant({3, 10}, x), w.tensor(), b.tensor(), 2);
                  }),
            0);
}

TEST_F(OpsTest, BinaryOpsBroadcastValues) {
  Tensor a = constant({2, 3}, std::vector<float>{1, 2, 3, 4, 5, 6});
  Tensor row = constant({3}, std::vector<float>{10, 20, 30});
  Tensor col = constant({2, 1}, std::vector<float>{100, 200});
  Tensor s = constant({1}, std::vector<float>{2});
  const std::vector<float> plus_row = {11, 22, 33, 14, 25, 36};
  const std::vector<float> minus_col = {-99, -98, -97, -196, -195, -194};
  const std::vector<float> times_s = {2, 4, 6, 8, 10, 12};
  Tensor r1 = add(a, row), r2 = sub(a, col), r3 = mul(s, a), r4 = div(row, a);
  EXPECT_EQ(r3.shape(), a.shape());
  for (int i = 0; i < 6; ++i) {
    EXPECT_FLOAT_EQ(r1.data()[i], plus_row[i]);
    EXPECT_FLOAT_EQ(r2.data()[i], minus_col[i]);
    EXPECT_FLOAT_EQ(r3.data()[i], times_s[i]);
    EXPECT_FLOAT_EQ(r4.data()[i], row.data()[i % 3] / a.data()[i]);
  }
}

TEST_F(OpsTest, BinaryOpGradientsWithBroadcasting) {
  Parameter& a = input("a", {4, 5});
  Parameter& b = input("b", {4, 5}, 0.5f, 2.0f);
  Parameter& row = input("row", {1, 5}, 0.5f, 2.0f);
  Parameter& col = input("col", {4, 1}, 0.5f, 2.0f);
  Parameter& s = input("s", {1}, 0.5f, 2.0f);
  EXPECT_EQ(check("add", [&] { return add(a.tensor(), b.tensor()); }), 0);
  EXPECT_EQ(check("sub", [&] { return sub(a.tensor(), b.tensor()); }), 0);
  EXPECT_EQ(check("mul", [&] { return mul(a.tensor(), b.tensor()); }), 0);
  EXPECT_EQ(check("div", [&] { return div(a.tensor(), b.tensor()); }), 0);
  EXPECT_EQ(check("add row", [&] { return add(a.tensor(), row.tensor()); }), 0);
  EXPECT_EQ(check("sub col", [&] { return sub(col.tensor(), a.tensor()); }), 0);
  EXPECT_EQ(check("mul scalar", [&] { return mul(s.tensor(), a.tensor()); }), 0);
  EXPECT_EQ(check("div row", [&] { return div(a.tensor(), row.tensor()); }), 0);
  EXPECT_EQ(check("div col", [&] { return div(col.tensor(), a.tensor() * 0.1f + 2.0f); }), 0);
  EXPECT_EQ(check("outer", [&] { return mul(col.tensor(), row.tensor()); }), 0);
}

TEST_F(OpsTest, ScalarOpGradients) {
  Parameter& x = input("x", {3, 4});
  EXPECT_EQ(check("scale", [&] { return scale(x.tensor(), -1.5f); }), 0);
  EXPECT_EQ(check("add_scalar", [&] { return add_scalar(x.tensor(), 3.0f); }), 0);
  EXPECT_EQ(check("rsub", [&] { return 1.0f - x.tensor(); }), 0);
  EXPECT_EQ(check("neg", [&] { return -x.tensor(); }), 0);
}

TEST_F(OpsTest, UnaryGradients) {
  Parameter& x = input("x", {6, 7}, -2.0f, 2.0f);
  avoid(x, 0.0f);
  Parameter& pos = input("pos", {6, 7}, 0.2f, 3.0f);
  EXPECT_EQ(check("silu", [&] { return silu(x.tensor()); }), 0);
  EXPECT_EQ(check("elu", [&] { return elu(x.tensor()); }), 0);
  EXPECT_EQ(check("relu", [&] { return relu(x.tensor()); }), 0);
  EXPECT_EQ(check("sigmoid", [&] { return sigmoid(x.tensor()); }), 0);
  EXPECT_EQ(check("tanh", [&] { return tanh(x.tensor()); }), 0);
  EXPECT_EQ(check("exp", [&] { return exp(x.tensor()); }), 0);
  EXPECT_EQ(check("log", [&] { return log(pos.tensor()); }), 0);
  EXPECT_EQ(check("square", [&] { return square(x.tensor()); }), 0);
  EXPECT_EQ(check("sqrt", [&] { return sqrt(pos.tensor()); }), 0);
  EXPECT_EQ(check("softplus", [&] { return softplus(x.tensor()); }), 0);
  EXPECT_EQ(check("symlog", [&] { return symlog(x.tensor()); }), 0);
  EXPECT_EQ(check("symexp", [&] { return symexp(x.tensor()); }), 0);
}

TEST_F(OpsTest, UnaryValues) {
  Tensor x = constant({5}, std::vector<float>{-3.0f, -0.5f, 0.0f, 0.7f, 4.0f});
  Tensor sl = symlog(x), se = symexp(sl), el = elu(x), sp = softplus(x), si = silu(x);
  for (int i = 0; i < 5; ++i) {
    const float v = x.data()[i];
    EXPECT_NEAR(sl.data()[i], std::copysign(std::log1p(std::fabs(v)), v), 1e-6f);
    EXPECT_NEAR(se.data()[i], v, 1e-5f);
    EXPECT_NEAR(el.data()[i], v > 0 ? v : std::expm1(v), 1e-6f);
    EXPECT_NEAR(sp.data()[i], std::log1p(std::exp(v)), 1e-6f);
    EXPECT_NEAR(si.data()[i], v / (1.0f + std::exp(-v)), 1e-6f);
  }
}

TEST_F(OpsTest, ClampAndMaximumMaskGradients) {
  Parameter& x = input("x", {4, 6}, -2.0f, 2.0f);
  avoid(x, -1.0f);
  avoid(x, 1.0f);
  avoid(x, 0.5f);
  EXPECT_EQ(check("clamp", [&] { return clamp(x.tensor(), -1.0f, 1.0f); }), 0);
  EXPECT_EQ(check("maximum", [&] { return maximum(x.tensor(), 0.5f); }), 0);
  // Outside the range the gradient is exactly zero.
  current_graph().reset();
  in_.zero_grad();
  current_graph().backward(sum(clamp(x.tensor(), -1.0f, 1.0f)));
  for (std::size_t i = 0; i < x.value().size(); ++i)
    EXPECT_EQ(x.grad()[i], std::fabs(x.value()[i]) <= 1.0f ? 1.0f : 0.0f);
}

TEST_F(OpsTest, StopGradientBlocksFlow) {
  Parameter& x = input("x", {3, 3});
  current_graph().backward(sum(mul(x.tensor(), stop_gradient(x.tensor()))));
  // d/dx sum(x * sg(x)) = sg(x) = x, not 2x.
  for (std::size_t i = 0; i < 9; ++i) EXPECT_FLOAT_EQ(x.grad()[i], x.value()[i]);
}

TEST_F(OpsTest, ShapeOpGradients) {
  Parameter& a = input("a", {2, 3, 4});
  Parameter& b = input("b", {2, 3, 2});
  Parameter& c = input("c", {2, 1, 4});
  EXPECT_EQ(check("reshape", [&] { return square(reshape(a.tensor(), Shape{6, 4})); }), 0);
  EXPECT_EQ(check("concat last", [&] { return concat({a.tensor(), b.tensor()}, -1); }), 0);
  EXPECT_EQ(check("concat middle", [&] { return concat({a.tensor(), c.tensor()}, 1); }), 0);
  EXPECT_EQ(check("concat many",
                  [&] {
                    return concat({a.tensor(), b.tensor(), a.tensor(), b.tensor(), a.tensor()}, -1);
                  }),
            0);
  EXPECT_EQ(check("slice last", [&] { return slice(a.tensor(), 1, 3); }), 0);
  EXPECT_EQ(check("slice first", [&] { return slice(a.tensor(), 1, 2, 0); }), 0);
  EXPECT_EQ(check("slice middle", [&] { return slice(a.tensor(), 0, 2, 1); }), 0);
}

TEST_F(OpsTest, ConcatAndSliceValues) {
  Tensor a = constant({2, 2}, std::vector<float>{1, 2, 3, 4});
  Tensor b = constant({2, 1}, std::vector<float>{5, 6});
  Tensor c = concat({a, b});
  const std::vector<float> expect = {1, 2, 5, 3, 4, 6};
  ASSERT_EQ(c.shape(), (Shape{2, 3}));
  for (int i = 0; i < 6; ++i) EXPECT_EQ(c.data()[i], expect[i]);
  Tensor s = slice(c, 1, 3);
  const std::vector<float> expect_s = {2, 5, 4, 6};
  for (int i = 0; i < 4; ++i) EXPECT_EQ(s.data()[i], expect_s[i]);
  std::vector<Tensor> many;
  for (int i = 0; i < 7; ++i) many.push_back(full({1, 2}, static_cast<float>(i)));
  Tensor rows = concat(many, 0);
  ASSERT_EQ(rows.shape(), (Shape{7, 2}));
  for (int i = 0; i < 14; ++i) EXPECT_EQ(rows.data()[i], static_cast<float>(i / 2));
}

TEST_F(OpsTest, ReductionGradientsAndValues) {
  Parameter& x = input("x", {3, 4, 5});
  EXPECT_EQ(check("sum", [&] { return sum(x.tensor()); }), 0);
  EXPECT_EQ(check("mean", [&] { return mean(x.tensor()); }), 0);
  EXPECT_EQ(check("sum 0", [&] { return sum(x.tensor(), 0); }), 0);
  EXPECT_EQ(check("sum 1", [&] { return sum(x.tensor(), 1); }), 0);
  EXPECT_EQ(check("mean -1", [&] { return mean(x.tensor(), -1); }), 0);
  Tensor s = sum(x.tensor(), 1);
  ASSERT_EQ(s.shape(), (Shape{3, 5}));
  float expect = 0;
  for (int j = 0; j < 4; ++j) expect += x.value()[2 * 20 + j * 5 + 3];
  EXPECT_NEAR(s.data()[2 * 5 + 3], expect, 1e-5f);
  EXPECT_EQ(sum(x.tensor()).shape().rank, 0);
}

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

// Direct NHWC convolution for reference; w is (K*K*C, O) ordered (ky, kx, c).
std::vector<float> naive_conv(const Parameter& x, const Parameter& w, int k, int s, int p, int oh,
                              int ow, int oc) {
  const Shape& xs = x.shape();
  const int n = static_cast<int>(xs.dims[0]), h = static_cast<int>(xs.dims[1]),
            wd = static_cast<int>(xs.dims[2]), c = static_cast<int>(xs.dims[3]);
  std::vector<float> y(static_cast<std::size_t>(n) * oh * ow * oc, 0.0f);
  for (int b = 0; b < n; ++b)
    for (int oy = 0; oy < oh; ++oy)
      for (int ox = 0; ox < ow; ++ox)
        for (int o = 0; o < oc; ++o) {
          double acc = 0;
          for (int ky = 0; ky < k; ++ky)
            for (int kx = 0; kx < k; ++kx)
              for (int ch = 0; ch < c; ++ch) {
                const int iy = oy * s - p + ky, ix = ox * s - p + kx;
                if (iy < 0 || iy >= h || ix < 0 || ix >= wd) continue;
                acc += x.value()[((b * h + iy) * wd + ix) * c + ch] *
                       w.value()[((ky * k + kx) * c + ch) * oc + o];
              }
          y[((b * oh + oy) * ow + ox) * oc + o] = static_cast<float>(acc);
        }
  return y;
}

TEST_F(OpsTest, Conv2dMatchesDirectConvolution) {
  Parameter& x = input("x", {2, 8, 6, 3});
  Parameter& w = input("w", {16 * 3, 5});
  Tensor y = conv2d(x.tensor(), w.tensor());
  ASSERT_EQ(y.shape(), (Shape{2, 4, 3, 5}));
  const auto expect = naive_conv(x, w, 4, 2, 1, 4, 3, 5);
  for (std::size_t i = 0; i < expect.size(); ++i) EXPECT_NEAR(y.data()[i], expect[i], 1e-4f);
  // Another geometry: kernel 3, stride 1, padding 1 keeps the size.
  Parameter& w3 = input("w3", {9 * 3, 2});
  Tensor y3 = conv2d(x.tensor(), w3.tensor(), {}, {.kernel = 3, .stride = 1, .padding = 1});
  ASSERT_EQ(y3.shape(), (Shape{2, 8, 6, 2}));
  const auto expect3 = naive_conv(x, w3, 3, 1, 1, 8, 6, 2);
  for (std::size_t i = 0; i < expect3.size(); ++i) EXPECT_NEAR(y3.data()[i], expect3[i], 1e-4f);
}

TEST_F(OpsTest, ConvTransposeIsTheAdjointOfConv) {
  // <conv2d(x, w), y> == <x, conv_transpose2d(y, w^T)> for every x, y.
  Parameter& x = input("x", {2, 8, 8, 3});
  Parameter& w = input("w", {16 * 3, 4});
  Parameter& y = input("y", {2, 4, 4, 4});
  Tensor wt = empty({4, 16 * 3});
  for (int i = 0; i < 48; ++i)
    for (int o = 0; o < 4; ++o) wt.data()[o * 48 + i] = w.value()[i * 4 + o];
  Tensor cx = conv2d(x.tensor(), w.tensor());
  Tensor ty = conv_transpose2d(y.tensor(), wt);
  ASSERT_EQ(ty.shape(), x.shape());
  double lhs = 0, rhs = 0;
  for (std::int64_t i = 0; i < cx.numel(); ++i) lhs += cx.data()[i] * y.value()[i];
  for (std::int64_t i = 0; i < ty.numel(); ++i) rhs += ty.data()[i] * x.value()[i];
  EXPECT_NEAR(lhs, rhs, 1e-3 * std::fabs(lhs) + 1e-3);
}

TEST_F(OpsTest, ConvGradients) {
  Parameter& x = input("x", {2, 6, 6, 2});
  Parameter& w = input("w", {16 * 2, 3});
  Parameter& b = input("b", {3});
  EXPECT_EQ(check("conv2d", [&] { return conv2d(x.tensor(), w.tensor(), b.tensor()); }), 0);
  Parameter& xt = input("xt", {2, 3, 3, 3});
  Parameter& wt = input("wt", {3, 16 * 2});
  Parameter& bt = input("bt", {2});
  EXPECT_EQ(check("conv_transpose2d",
                  [&] { return conv_transpose2d(xt.tensor(), wt.tensor(), bt.tensor()); }),
            0);
}

TEST_F(OpsTest, CategoricalOps) {
  Parameter& logits = input("logits", {3, 2 * 4}, -2.0f, 2.0f);
  Parameter& other = input("other", {3, 2 * 4}, -2.0f, 2.0f);
  EXPECT_EQ(check("unimix", [&] { return unimix_probs(logits.tensor(), 4); }), 0);
  EXPECT_EQ(check("kl",
                  [&] {
                    return kl_categorical(unimix_probs(logits.tensor(), 4),
                                          unimix_probs(other.tensor(), 4));
                  }),
            0);
  EXPECT_EQ(check("entropy",
                  [&] {
                    return entropy(softmax(reshape(logits.tensor(), Shape{6, 4})));
                  }),
            0);
  Tensor p = unimix_probs(logits.tensor(), 4);
  for (std::int64_t i = 0; i < p.numel(); ++i) EXPECT_GE(p.data()[i], 0.01f / 4 - 1e-7f);
  EXPECT_NEAR(kl_categorical(p, p).data()[0], 0.0f, 1e-6f);
  // KL against the uniform distribution is log(classes) - entropy, per group, summed.
  Tensor u = full(p.shape(), 0.25f);
  Tensor kl = kl_categorical(p, u);
  Tensor h = entropy(reshape(p, Shape{6, 4}));
  EXPECT_NEAR(kl.data()[1], 2 * std::log(4.0f) - h.data()[2] - h.data()[3], 1e-5f);
}

TEST_F(OpsTest, StraightThroughSampleIsOneHotWithIdentityGradient) {
  Parameter& logits = input("logits", {2, 3 * 5}, -2.0f, 2.0f);
  Rng rng(5);
  Tensor probs = unimix_probs(logits.tensor(), 5);
  Tensor sample = sample_straight_through(probs, 5, rng);
  for (int g = 0; g < 6; ++g) {
    float total = 0;
    for (int c = 0; c < 5; ++c) {
      const float v = sample.data()[g * 5 + c];
      EXPECT_TRUE(v == 0.0f || v == 1.0f);
      total += v;
    }
    EXPECT_EQ(total, 1.0f);
  }
  // The gradient through the sample equals the gradient through probs.
  Tensor weights = constant(sample.shape(), std::vector<float>(30, 0.0f));
  for (int i = 0; i < 30; ++i) weights.data()[i] = static_cast<float>(i % 7) - 3.0f;
  current_graph().backward(sum(mul(sample, weights)));
  std::vector<float> via_sample(logits.grad().begin(), logits.grad().end());
  in_.zero_grad();
  current_graph().reset();
  Tensor probs2 = unimix_probs(logits.tensor(), 5);
  Tensor weights2 = constant(probs2.shape(), std::vector<float>(30, 0.0f));
  for (int i = 0; i < 30; ++i) weights2.data()[i] = static_cast<float>(i % 7) - 3.0f;
  current_graph().backward(sum(mul(probs2, weights2)));
  for (int i = 0; i < 30; ++i) EXPECT_FLOAT_EQ(via_sample[i], logits.grad()[i]);
}

TEST_F(OpsTest, SamplingFollowsTheProbabilities) {
  // 20000 draws from (0.1, 0.6, 0.3): frequencies within 4 standard errors.
  std::vector<float> probs;
  for (int i = 0; i < 20000; ++i) probs.insert(probs.end(), {0.1f, 0.6f, 0.3f});
  Rng rng(3);
  Tensor s = sample_straight_through(constant({20000, 3}, probs), 3, rng);
  double counts[3] = {0, 0, 0};
  for (int i = 0; i < 20000; ++i)
    for (int c = 0; c < 3; ++c) counts[c] += s.data()[i * 3 + c];
  const double expect[3] = {0.1, 0.6, 0.3};
  for (int c = 0; c < 3; ++c) {
    const double se = std::sqrt(expect[c] * (1 - expect[c]) / 20000);
    EXPECT_NEAR(counts[c] / 20000, expect[c], 4 * se);
  }
}

TEST_F(OpsTest, TwoHotEncodingAndLoss) {
  // The encoding puts its mass on the two bins around symlog(t), with the right mean.
  Tensor t = constant({4}, std::vector<float>{0.0f, 3.7f, -150.0f, 1e12f});
  Tensor enc = twohot(t);
  ASSERT_EQ(enc.shape(), (Shape{4, kTwoHotBins}));
  const float step = (kTwoHotHigh - kTwoHotLow) / (kTwoHotBins - 1);
  for (int r = 0; r < 3; ++r) {
    double total = 0, mean_bin = 0;
    int nonzero = 0;
    for (int k = 0; k < kTwoHotBins; ++k) {
      const float v = enc.data()[r * kTwoHotBins + k];
      total += v;
      mean_bin += v * (kTwoHotLow + k * step);
      nonzero += v != 0.0f;
    }
    EXPECT_NEAR(total, 1.0, 1e-6);
    EXPECT_LE(nonzero, 2);
    const float v = t.data()[r];
    EXPECT_NEAR(mean_bin, std::copysign(std::log1p(std::fabs(v)), v), 1e-5);
  }
  EXPECT_EQ(enc.data()[3 * kTwoHotBins + kTwoHotBins - 1], 1.0f);  // clipped to the last bin

  Parameter& logits = input("logits", {3, kTwoHotBins}, -1.0f, 1.0f);
  const std::vector<float> targets = {0.5f, -8.0f, 40.0f};
  // Constants are made inside the lambdas: the check resets the graph between evaluations.
  EXPECT_EQ(check("twohot ce",
                  [&] { return twohot_cross_entropy(logits.tensor(), constant({3}, targets)); }),
            0);
  EXPECT_EQ(check("twohot mean", [&] { return twohot_mean(logits.tensor()); },
                  {.step = 1e-2f, .atol = 5e-3f, .rtol = 3e-2f}),
            0);
  // Logits that put all mass on the encoding decode back to the target.
  Tensor target = constant({3}, targets);
  Tensor exact = log(add_scalar(twohot(target), 1e-30f));
  Tensor decoded = twohot_mean(exact);
  for (int r = 0; r < 3; ++r)
    EXPECT_NEAR(decoded.data()[r], target.data()[r], 1e-3f * std::fabs(target.data()[r]));
}

TEST_F(OpsTest, LossGradientsAndValues) {
  Parameter& x = input("x", {4, 3}, -3.0f, 3.0f);
  std::vector<float> targets(12);
  for (int i = 0; i < 12; ++i) targets[i] = static_cast<float>(i % 2);
  EXPECT_EQ(check("bce",
                  [&] {
                    return bce_with_logits(x.tensor(), constant({4, 3}, targets));
                  }),
            0);
  EXPECT_EQ(check("squared_error",
                  [&] {
                    return squared_error(x.tensor(), constant({4, 3}, targets));
                  }),
            0);
  EXPECT_EQ(check("mse", [&] { return mse(x.tensor(), constant({4, 3}, targets)); }), 0);
  Tensor t = constant({4, 3}, targets);
  Tensor bce = bce_with_logits(x.tensor(), t);
  for (int i = 0; i < 12; ++i) {
    const double s = 1.0 / (1.0 + std::exp(-x.value()[i]));
    const double expect = -(targets[i] * std::log(s) + (1 - targets[i]) * std::log(1 - s));
    EXPECT_NEAR(bce.data()[i], expect, 1e-5);
  }
}

}  // namespace
}  // namespace indrive::nn
