// Tests of icm.cc, the ICM baseline.
#include "indrive/agent/icm.h"

#include <gtest/gtest.h>

#include <cmath>

#include "indrive/nn/kernels.h"
#include "intrinsic_test_support.h"

namespace indrive::agent {
namespace {

using nn::Shape;
using nn::Tensor;
using namespace testing;

TEST(Icm, ForwardErrorRewardIsHigherOnUnseenTransitions) {
  nn::set_threads(1);
  nn::Rng rng(7);
  const WorldModelConfig model = preset("tiny").world_model;
  Icm icm(small_intrinsic(Method::kIcm), model, rng);
  float first = 0, last = 0;
  const auto [seen, unseen] = seen_vs_unseen(icm, model, 150, &first, &last);
  std::printf("ICM loss %.3f -> %.3f, reward seen %.3g unseen %.3g\n", first, last, seen, unseen);
  EXPECT_LT(last, 0.5f * first);
  EXPECT_GT(unseen, seen + 0.25f);  // normalised rewards, well apart
}

}  // namespace
}  // namespace indrive::agent
