#include "indrive/agent/rate_limiter.h"

#include <gtest/gtest.h>

#include <limits>
#include <random>

namespace indrive::agent {
namespace {

TEST(RateLimiterTest, UpdatesFallDueAtTheRatioAfterPrefill) {
  RateLimiter rate({.replay_ratio = 32, .steps_per_update = 128, .prefill = 100, .slack = 16});
  EXPECT_EQ(rate.updates_due(99), 0);
  EXPECT_EQ(rate.updates_due(100), 25);  // 32 * 100 / 128
  EXPECT_EQ(rate.updates_due(104), 26);
  // After 25 updates the 26th is due at 104 steps, so actors may go to 104 + slack.
  EXPECT_EQ(rate.allowance(25, 100), 104u + 16u);
  // Before prefill the floor rules.
  EXPECT_EQ(rate.allowance(0, 100), 100u + 16u);
}

TEST(RateLimiterTest, AsyncLiftsTheLimit) {
  RateLimiter rate({.replay_ratio = 32, .steps_per_update = 128, .async = true});
  EXPECT_EQ(rate.allowance(0, 0), std::numeric_limits<std::uint64_t>::max());
}

// Two actors of very different, random speeds and a learner of random speed, all paced by the
// allowance as the service does it (an actor counts what the learner received plus its own
// unsent steps): the ratio at the end is the configured one whatever the speeds, no actor
// deadlocks holding a partial chunk, and together they overshoot by at most one chunk.
TEST(RateLimiterTest, RatioHoldsWhateverTheSpeedsOfActorsAndLearner) {
  for (std::uint64_t seed : {1u, 2u, 3u}) {
    std::mt19937_64 rng(seed);
    const std::int64_t chunk = 16;
    RateLimiter rate({.replay_ratio = 8, .steps_per_update = 64, .prefill = 200, .slack = chunk});
    std::int64_t received = 0, updates = 0;
    std::int64_t open[2] = {0, 0};  // steps in each actor's open chunk
    std::int64_t taken = 0;
    const double actor_speed[2] = {std::uniform_real_distribution<>(0.1, 1.0)(rng),
                                   std::uniform_real_distribution<>(0.1, 1.0)(rng)};
    const double learner_speed = std::uniform_real_distribution<>(0.05, 1.0)(rng);
    std::uniform_real_distribution<> coin(0.0, 1.0);
    for (int tick = 0; tick < 200000 && received < 20000; ++tick) {
      const std::uint64_t allowed = rate.allowance(updates, 0);
      for (int a = 0; a < 2; ++a) {
        if (coin(rng) > actor_speed[a]) continue;
        if (static_cast<std::uint64_t>(received + open[a]) >= allowed) continue;
        ++open[a];
        ++taken;
        if (open[a] == chunk) {
          received += chunk;
          open[a] = 0;
        }
      }
      EXPECT_LE(taken, static_cast<std::int64_t>(allowed) + chunk);
      if (coin(rng) < learner_speed && updates < rate.updates_due(received)) ++updates;
    }
    ASSERT_GE(received, 20000) << "the actors must never deadlock (seed " << seed << ")";
    // Let the learner finish the updates it owes, as it does at the end of a run.
    updates = rate.updates_due(received);
    const double ratio = static_cast<double>(updates) * 64 / static_cast<double>(received);
    EXPECT_NEAR(ratio, 8.0, 8.0 * 0.05) << "seed " << seed;
  }
}

}  // namespace
}  // namespace indrive::agent
