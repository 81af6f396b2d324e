// Tests of ops_conv.cc: convolution and transposed convolution against a direct loop, and their
// gradients.
#include "ops_test_support.h"

namespace indrive::nn {
namespace {

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

}  // namespace
}  // namespace indrive::nn
