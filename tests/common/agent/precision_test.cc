// Mixed precision does not change what is learned. The dot environment's world model is
// trained twice from the same seeds, with fp32 and with bf16 products, and the task
// actor-critic is trained in imagination with bf16 products; the thresholds are those of the
// fp32 learning tests (world_model_test.cc, behavior_learning_test.cc). Skipped where the CPU
// has no native bf16 (precision_fallback_test.cc covers that case).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <vector>

#include "dot_learning.h"
#include "indrive/nn/kernels.h"

namespace indrive::agent {
namespace {

TEST(MixedPrecision, Bf16WorldModelLearnsTheDotEnvironmentAsFp32Does) {
  // Band, stated before measuring: every window's reconstruction error and KL of the bf16 run
  // within 25% (plus 0.5 nats or units, for values near zero) of the fp32 run's, and the fp32
  // test's own thresholds met by both. About 50 s on one core.
  if (!nn::bf16_supported()) GTEST_SKIP() << "no native bf16 here: " << nn::kernel_report();
  nn::set_threads(1);
  nn::set_precision(nn::Precision::kFp32);
  const dot_learning::TrainedWorldModel fp32;
  nn::set_precision(nn::Precision::kBf16);
  const dot_learning::TrainedWorldModel bf16;
  nn::current_graph().reset();
  nn::set_precision(nn::Precision::kFp32);
  for (std::size_t w = 0; w < fp32.recon.size(); ++w) {
    std::printf("window %2zu  recon fp32 %8.2f bf16 %8.2f   kl fp32 %6.3f bf16 %6.3f\n", w,
                fp32.recon[w], bf16.recon[w], fp32.kl[w], bf16.kl[w]);
  }
  for (std::size_t w = 0; w < fp32.recon.size(); ++w) {
    EXPECT_NEAR(bf16.recon[w], fp32.recon[w], 0.25f * fp32.recon[w] + 0.5f) << "window " << w;
    EXPECT_NEAR(bf16.kl[w], fp32.kl[w], 0.25f * fp32.kl[w] + 0.5f) << "window " << w;
  }
  for (const dot_learning::TrainedWorldModel* c : {&fp32, &bf16}) {
    EXPECT_LT(c->recon.back(), 0.1f * c->recon.front());
    EXPECT_LT(c->kl.back(), 0.9f * *std::max_element(c->kl.begin(), c->kl.end()));
  }
}

TEST(MixedPrecision, Bf16TaskActorCriticReachesTheRewardedCorner) {
  // The thresholds of behavior_learning_test.cc (after 700 world-model and 150 actor-critic
  // updates the mean imagined reward is above 0.4 and above twice the untrained actor's), with
  // every product in bf16. About 40 s on one core.
  if (!nn::bf16_supported()) GTEST_SKIP() << "no native bf16 here: " << nn::kernel_report();
  nn::set_threads(1);
  nn::set_precision(nn::Precision::kBf16);
  const dot_learning::CornerRewards r = dot_learning::train_task_actor_to_the_corner();
  nn::set_precision(nn::Precision::kFp32);
  std::printf("bf16: imagined reward per step: untrained actor %.3f, trained actor %.3f\n",
              r.before, r.after);
  EXPECT_GT(r.after, 0.4f);
  EXPECT_GT(r.after, 2.0f * r.before);
}

}  // namespace
}  // namespace indrive::agent
