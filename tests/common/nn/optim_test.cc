// Adam against a hand-written reference, clipping, warm-up, skipped steps, state round-trip,
// and EMA.
#include "indrive/nn/optim.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <vector>

#include "indrive/nn/nn.h"

namespace indrive::nn {
namespace {

TEST(AdamTest, MatchesReferenceUpdate) {
  ParamGroup g("g");
  Parameter& p = g.add("p", Shape{2});
  p.value()[0] = 1.0f;
  p.value()[1] = -2.0f;
  Adam adam(g, {.lr = 0.1f, .eps = 1e-8f, .clip = 0.0f});
  double w[2] = {1.0, -2.0}, m[2] = {0, 0}, v[2] = {0, 0};
  for (int t = 1; t <= 5; ++t) {
    // Gradient of sum(w^3).
    for (int i = 0; i < 2; ++i) p.grad()[i] = 3.0f * p.value()[i] * p.value()[i];
    adam.step();
    for (int i = 0; i < 2; ++i) {
      const double grad = 3.0 * w[i] * w[i];
      m[i] = 0.9 * m[i] + 0.1 * grad;
      v[i] = 0.999 * v[i] + 0.001 * grad * grad;
      const double mh = m[i] / (1 - std::pow(0.9, t)), vh = v[i] / (1 - std::pow(0.999, t));
      w[i] -= 0.1 * mh / (std::sqrt(vh) + 1e-8);
      EXPECT_NEAR(p.value()[i], w[i], 1e-5) << "step " << t;
      EXPECT_EQ(p.grad()[i], 0.0f);  // zeroed after the step
    }
  }
  EXPECT_EQ(adam.steps(), 5);
}

TEST(AdamTest, ClipsByGlobalNormAndWarmsUp) {
  ParamGroup g("g");
  Parameter& a = g.add("a", Shape{1});
  Parameter& b = g.add("b", Shape{1});
  Adam adam(g, {.lr = 1.0f, .clip = 1.0f, .warmup = 4});
  a.grad()[0] = 3.0f;
  b.grad()[0] = 4.0f;
  const StepStats stats = adam.step();
  EXPECT_FLOAT_EQ(stats.grad_norm, 5.0f);
  EXPECT_FLOAT_EQ(stats.lr, 0.25f);
  // First Adam step moves each weight by lr * sign(g) regardless of scale.
  EXPECT_NEAR(a.value()[0], -0.25f, 1e-5f);
  EXPECT_NEAR(b.value()[0], -0.25f, 1e-5f);
  EXPECT_FLOAT_EQ(grad_norm(g), 0.0f);
  // Clipping scales the gradient, which shows in the second moment after a second step.
  ParamGroup h("h");
  Parameter& c = h.add("c", Shape{1});
  Adam clipped(h, {.lr = 1.0f, .clip = 1.0f});
  c.grad()[0] = 10.0f;
  clipped.step();
  const auto state = clipped.save_state();
  EXPECT_GT(state.size(), 16u);
}

TEST(AdamTest, SkipsNonFiniteGradients) {
  ParamGroup g("g");
  Parameter& p = g.add("p", Shape{2});
  Adam adam(g, {});
  p.grad()[0] = std::nanf("");
  const StepStats stats = adam.step();
  EXPECT_TRUE(stats.skipped);
  EXPECT_EQ(adam.skipped_steps(), 1);
  EXPECT_EQ(adam.steps(), 0);
  EXPECT_EQ(p.value()[0], 0.0f);
  EXPECT_EQ(p.grad()[0], 0.0f);
}

TEST(AdamTest, StateRoundTripContinuesIdentically) {
  auto make = [](ParamGroup& g) {
    Parameter& p = g.add("p", Shape{3});
    for (int i = 0; i < 3; ++i) p.value()[i] = 0.5f * i;
    return &p;
  };
  ParamGroup g1("g"), g2("g");
  Parameter* p1 = make(g1);
  Parameter* p2 = make(g2);
  Adam a1(g1, {.lr = 0.05f}), a2(g2, {.lr = 0.05f});
  auto grad = [](Parameter* p) {
    for (int i = 0; i < 3; ++i) p->grad()[i] = std::sin(p->value()[i]) + 0.1f * i;
  };
  for (int t = 0; t < 3; ++t) {
    grad(p1);
    a1.step();
  }
  // Copy weights and optimiser state into the second pair, then both continue.
  std::copy(p1->value().begin(), p1->value().end(), p2->value().begin());
  a2.load_state(a1.save_state());
  EXPECT_EQ(a2.steps(), 3);
  for (int t = 0; t < 3; ++t) {
    grad(p1);
    a1.step();
    grad(p2);
    a2.step();
  }
  for (int i = 0; i < 3; ++i) EXPECT_EQ(p1->value()[i], p2->value()[i]);
  // A state from another group is rejected with a message.
  ParamGroup other("other");
  other.add("p", Shape{3});
  Adam a3(other, {});
  EXPECT_THROW(a3.load_state(a1.save_state()), SerializationError);
  auto blob = a1.save_state();
  blob[blob.size() / 2] ^= 0x01;
  EXPECT_THROW(a2.load_state(blob), SerializationError);
}

// With a prefix, Adam optimises one head of a group: it clips by the norm of that head's
// gradients, moves and zeroes only them, and its state names only them; a prefix that matches
// nothing is a bug.
TEST(AdamTest, PrefixOptimisesOnlyTheParametersItNames) {
  ParamGroup g("model");
  Parameter& body = g.add("body.w", Shape{1});
  Parameter& head_w = g.add("head.w", Shape{1});
  Parameter& head_b = g.add("head.b", Shape{1});
  Adam adam(g, {.lr = 1.0f, .clip = 0.0f}, "head.");
  body.grad()[0] = 12.0f;
  head_w.grad()[0] = 3.0f;
  head_b.grad()[0] = -4.0f;
  const StepStats stats = adam.step();
  EXPECT_FLOAT_EQ(stats.grad_norm, 5.0f);  // not 13: the body's gradient is not the head's
  EXPECT_EQ(body.value()[0], 0.0f);
  EXPECT_EQ(body.grad()[0], 12.0f);  // left for whoever owns it
  EXPECT_NEAR(head_w.value()[0], -1.0f, 1e-5f);
  EXPECT_NEAR(head_b.value()[0], 1.0f, 1e-5f);
  EXPECT_EQ(head_w.grad()[0], 0.0f);
  EXPECT_EQ(head_b.grad()[0], 0.0f);
  // Its state round-trips into another head optimiser of the same group, not into the whole.
  ParamGroup g2("model");
  g2.add("body.w", Shape{1});
  g2.add("head.w", Shape{1});
  g2.add("head.b", Shape{1});
  Adam head2(g2, {}, "head."), whole2(g2, {});
  head2.load_state(adam.save_state());
  EXPECT_EQ(head2.steps(), 1);
  EXPECT_THROW(whole2.load_state(adam.save_state()), SerializationError);
  EXPECT_DEATH(Adam(g, {}, "tail."), "starts with 'tail.'");
}

// A parameter large enough for the update to be split over threads (the small ones above run
// in one piece): every element against the reference in double, with clipping, and the same
// bits with 1 and 2 threads.
TEST(AdamTest, LargeParameterMatchesReferenceWithAnyThreadCount) {
  constexpr int kSize = 150000;
  auto run = [](int threads) {
    const int saved = nn::threads();
    set_threads(threads);
    ParamGroup g("g");
    Parameter& p = g.add("p", Shape{kSize});
    for (int i = 0; i < kSize; ++i) p.value()[i] = std::sin(0.001f * i);
    Adam adam(g, {.lr = 0.01f, .eps = 1e-8f, .clip = 50.0f});
    for (int t = 0; t < 3; ++t) {
      for (int i = 0; i < kSize; ++i) p.grad()[i] = std::cos(0.002f * i + t) * (1 + i % 7);
      adam.step();
    }
    set_threads(saved);
    return std::vector<float>(p.value().begin(), p.value().end());
  };
  const std::vector<float> one = run(1), two = run(2);
  ASSERT_EQ(one.size(), two.size());
  EXPECT_EQ(std::memcmp(one.data(), two.data(), one.size() * sizeof(float)), 0);
  // The reference: the same three steps in double, clipped by the global norm.
  std::vector<double> w(kSize), m(kSize, 0.0), v(kSize, 0.0), grad(kSize);
  for (int i = 0; i < kSize; ++i) w[i] = std::sin(0.001f * i);
  for (int t = 1; t <= 3; ++t) {
    double norm = 0;
    for (int i = 0; i < kSize; ++i) {
      grad[i] = static_cast<float>(std::cos(0.002f * i + (t - 1)) * (1 + i % 7));
      norm += grad[i] * grad[i];
    }
    norm = std::sqrt(norm);
    const double clip = norm > 50.0 ? 50.0 / norm : 1.0;
    for (int i = 0; i < kSize; ++i) {
      const double gi = grad[i] * clip;
      m[i] = 0.9 * m[i] + 0.1 * gi;
      v[i] = 0.999 * v[i] + 0.001 * gi * gi;
      const double mh = m[i] / (1 - std::pow(0.9, t)), vh = v[i] / (1 - std::pow(0.999, t));
      w[i] -= 0.01 * mh / (std::sqrt(vh) + 1e-8);
    }
  }
  int off = 0;
  for (int i = 0; i < kSize; ++i) off += std::fabs(one[i] - w[i]) > 1e-5;
  EXPECT_EQ(off, 0) << "elements away from the reference";
}

TEST(EmaTest, MovesTowardsTheSource) {
  ParamGroup src("critic"), dst("slow_critic");
  Parameter& s = src.add("w", Shape{2});
  Parameter& d = dst.add("w", Shape{2});
  s.value()[0] = 1.0f;
  s.value()[1] = -1.0f;
  Ema ema(src, dst, 0.02f);
  ema.update();
  EXPECT_FLOAT_EQ(d.value()[0], 0.02f);
  for (int i = 0; i < 500; ++i) ema.update();
  EXPECT_NEAR(d.value()[1], -1.0f, 1e-4f);
  ema.copy();
  EXPECT_EQ(d.value()[0], 1.0f);
  ParamGroup wrong("wrong");
  wrong.add("w", Shape{3});
  EXPECT_THROW(Ema(src, wrong), SerializationError);
}

}  // namespace
}  // namespace indrive::nn
