// Shapes, the graph's arena and backward pass, no-grad mode, parameters and the RNG.
#include "indrive/common/nn/tensor.h"

#include <gtest/gtest.h>

#include <cmath>

#include "indrive/common/nn/nn.h"

namespace indrive::nn {
namespace {

TEST(ShapeTest, DimensionsRowsAndCols) {
  Shape s{16, 64, 3};
  EXPECT_EQ(s.rank, 3);
  EXPECT_EQ(s.numel(), 16 * 64 * 3);
  EXPECT_EQ(s.rows(), 16 * 64);
  EXPECT_EQ(s.cols(), 3);
  EXPECT_EQ(s[-1], 3);
  EXPECT_EQ(s.str(), "(16, 64, 3)");
  EXPECT_EQ(Shape().numel(), 1);
  EXPECT_NE(s, (Shape{16, 64, 4}));
}

TEST(GraphTest, GradientsAccumulateOverUsesAndCalls) {
  Graph& g = current_graph();
  g.reset();
  ParamGroup group("g");
  Parameter& p = group.add("p", Shape{3});
  for (float& v : p.value()) v = 2.0f;
  // d/dp sum(p * p + p) = 2p + 1 = 5.
  Tensor x = p.tensor();
  g.backward(sum(add(mul(x, x), x)));
  for (float v : p.grad()) EXPECT_FLOAT_EQ(v, 5.0f);
  // A second graph adds to the same parameter gradient until zero_grad.
  g.reset();
  g.backward(sum(p.tensor()));
  for (float v : p.grad()) EXPECT_FLOAT_EQ(v, 6.0f);
  group.zero_grad();
  for (float v : p.grad()) EXPECT_EQ(v, 0.0f);
}

TEST(GraphTest, NoGradModeRecordsNothing) {
  Graph& g = current_graph();
  g.reset();
  ParamGroup group("g");
  Parameter& p = group.add("p", Shape{2, 2});
  for (float& v : p.value()) v = 1.5f;
  Tensor y;
  {
    NoGradGuard no_grad;
    EXPECT_FALSE(g.grad_enabled());
    y = sum(tanh(p.tensor()));
  }
  EXPECT_TRUE(g.grad_enabled());
  EXPECT_FALSE(y.requires_grad());
  EXPECT_NEAR(y.item(), 4 * std::tanh(1.5f), 1e-6f);
  g.backward(y);  // nothing to do
  for (float v : p.grad()) EXPECT_EQ(v, 0.0f);
}

TEST(GraphTest, ConstantsGetNoGradient) {
  Graph& g = current_graph();
  g.reset();
  Tensor c = full({2}, 3.0f);
  Tensor leaf = grad_leaf({2}, std::vector<float>{1.0f, 2.0f});
  g.backward(sum(mul(c, leaf)));
  EXPECT_EQ(c.grad(), nullptr);
  ASSERT_NE(leaf.grad(), nullptr);
  EXPECT_FLOAT_EQ(leaf.grad()[0], 3.0f);
}

// One small training step's worth of ops.
void training_step(Mlp& net, Adam& adam, int rows) {
  Graph& g = current_graph();
  g.reset();
  Tensor x = full({rows, 8}, 0.25f);
  Tensor y = full({rows, 1}, 1.0f);
  g.backward(mse(net(x), y));
  adam.step();
}

TEST(GraphTest, SteadyStateStepsDoNotAllocate) {
  Rng rng(1);
  ParamGroup group("model");
  Mlp net(group, "net", 8, {.units = 64, .layers = 3, .out = 1}, rng);
  Adam adam(group, {});
  Graph& g = current_graph();
  // A step larger than the arena's first block forces growth; reset then merges the blocks.
  training_step(net, adam, 20000);
  training_step(net, adam, 20000);
  const std::size_t allocations = g.arena_system_allocations();
  const std::size_t capacity = g.arena_capacity_bytes();
  for (int i = 0; i < 5; ++i) training_step(net, adam, 20000);
  EXPECT_EQ(g.arena_system_allocations(), allocations);
  EXPECT_EQ(g.arena_capacity_bytes(), capacity);
  EXPECT_GT(g.num_nodes(), 10u);
  g.reset();
  EXPECT_EQ(g.arena_used_bytes(), 0u);
}

TEST(RngTest, DeterministicAndRoughlyNormal) {
  Rng a(42), b(42), c(43);
  EXPECT_EQ(a.next_u64(), b.next_u64());
  EXPECT_NE(a.next_u64(), c.next_u64());
  Rng r(7);
  double mean = 0, var = 0;
  const int n = 100000;
  for (int i = 0; i < n; ++i) {
    const double z = r.normal();
    mean += z / n;
    var += z * z / n;
  }
  EXPECT_NEAR(mean, 0.0, 0.02);
  EXPECT_NEAR(var, 1.0, 0.02);
  for (int i = 0; i < 1000; ++i) {
    const float u = r.uniform();
    EXPECT_GE(u, 0.0f);
    EXPECT_LT(u, 1.0f);
    EXPECT_LT(r.below(9), 9);
  }
}

}  // namespace
}  // namespace indrive::nn
