// Tests of ops_elementwise.cc: binary ops with broadcasting, scalar and unary ops, clamp and
// maximum.
#include "ops_test_support.h"

namespace indrive::nn {
namespace {

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

}  // namespace
}  // namespace indrive::nn
