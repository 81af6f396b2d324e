// Tests of rnd.cc, the RND baseline.
#include "indrive/agent/rnd.h"

#include <gtest/gtest.h>

#include <cmath>

#include "indrive/nn/kernels.h"
#include "intrinsic_test_support.h"

namespace indrive::agent {
namespace {

using nn::Shape;
using nn::Tensor;
using namespace testing;

TEST(Rnd, PredictorLearnsAndTheTargetStaysFixed) {
  nn::set_threads(1);
  nn::Rng rng(8);
  const WorldModelConfig model = preset("tiny").world_model;
  Rnd rnd(small_intrinsic(Method::kRnd), model, rng);
  std::vector<float> target_before;
  for (const auto& p : rnd.target_params().params())
    target_before.insert(target_before.end(), p->value().begin(), p->value().end());
  float first = 0, last = 0;
  const auto [seen, unseen] = seen_vs_unseen(rnd, model, 150, &first, &last);
  std::printf("RND loss %.3f -> %.3f, reward seen %.3g unseen %.3g\n", first, last, seen, unseen);
  EXPECT_LT(last, 0.5f * first);
  EXPECT_GT(unseen, seen + 0.25f);
  std::vector<float> target_after;
  for (const auto& p : rnd.target_params().params())
    target_after.insert(target_after.end(), p->value().begin(), p->value().end());
  EXPECT_EQ(target_before, target_after);
}

}  // namespace
}  // namespace indrive::agent
