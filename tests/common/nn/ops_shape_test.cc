// Tests of ops_shape.cc: stop-gradient, reshape, concat, slice and reductions.
#include "ops_test_support.h"

namespace indrive::nn {
namespace {

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

}  // namespace
}  // namespace indrive::nn
