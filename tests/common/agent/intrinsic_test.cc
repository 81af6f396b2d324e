// What every intrinsic module (intrinsic.h) must do: train on the replay's transitions without
// sending gradients into the world model.
#include "indrive/agent/intrinsic.h"

#include <gtest/gtest.h>

#include <cmath>

#include "dot_env.h"
#include "intrinsic_test_support.h"

namespace indrive::agent {
namespace {

using nn::Shape;
using nn::Tensor;
using namespace testing;

class IntrinsicStopGradient : public ::testing::TestWithParam<Method> {};

TEST_P(IntrinsicStopGradient, WorldModelGetsNoGradientAndModuleDoes) {
  nn::Rng rng(4);
  const WorldModelConfig model = preset("tiny").world_model;
  WorldModel wm(model, rng);
  auto module = make_intrinsic(small_intrinsic(GetParam()), model, rng);
  ReplayBuffer replay({.capacity = 1000, .height = 32, .width = 32, .seed = 2});
  synthetic::DotEnv env(32, 1);
  synthetic::collect_random(env, replay, 100, 3);
  const SequenceBatch batch = replay.sample(2, 6);
  nn::current_graph().reset();
  wm.params().zero_grad();
  WorldModelOutput out = wm.observe(batch, false, rng);
  Transitions tr = make_transitions(out.features, out.post_probs,
                                    WorldModel::action_one_hot(batch.actions, 2, 6),
                                    WorldModel::time_major_column(batch.is_first, 2, 6), 2);
  nn::current_graph().backward(module->loss(tr));
  for (const auto& p : wm.params().params()) {
    for (float g : p->grad()) ASSERT_EQ(g, 0.0f) << p->name();
  }
  EXPECT_GT(nn::grad_norm(module->params()), 0.0f);
}

INSTANTIATE_TEST_SUITE_P(AllMethods, IntrinsicStopGradient,
                         ::testing::Values(Method::kDisag, Method::kIcm, Method::kRnd));

}  // namespace
}  // namespace indrive::agent
