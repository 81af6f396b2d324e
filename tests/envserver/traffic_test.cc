#include "indrive/envserver/traffic.h"

#include <gtest/gtest.h>

#include <map>
#include <numbers>

#include "sim_test_net.h"
#include "testing.h"

namespace indrive::env {
namespace {

TEST(Density, OnlyThePaperSetOrZeroIsAccepted) {
  for (int ok : {0, 5, 10, 20}) EXPECT_NO_THROW(validate_density(ok));
  for (int bad : {-5, 1, 7, 15, 40}) {
    try {
      validate_density(bad);
      FAIL() << "expected EnvError for " << bad;
    } catch (const EnvError& e) {
      EXPECT_NE(std::string(e.what()).find(std::to_string(bad)), std::string::npos);
    }
  }
}

TEST(Density, PretrainingResamplesEveryPeriodFromTheSet) {
  std::map<int, int> seen;
  int changes = 0;
  for (std::int64_t period = 0; period < 300; ++period) {
    const int d = pretrain_density(7, period * 10000);
    // Constant inside a period.
    EXPECT_EQ(pretrain_density(7, period * 10000 + 9999), d);
    if (period > 0 && d != pretrain_density(7, (period - 1) * 10000)) ++changes;
    ++seen[d];
  }
  ASSERT_EQ(seen.size(), 3u);
  for (const auto& [density, count] : seen) {
    EXPECT_TRUE(density == 5 || density == 10 || density == 20);
    EXPECT_GT(count, 70) << density;  // roughly uniform over 300 periods
  }
  EXPECT_GT(changes, 150);
  // Another seed gives another schedule.
  int differ = 0;
  for (std::int64_t period = 0; period < 50; ++period) {
    differ += pretrain_density(7, period * 10000) != pretrain_density(8, period * 10000);
  }
  EXPECT_GT(differ, 10);
}

TEST(TrafficSpawn, OutsideTheViewConeNearbyAndInsideTheRadius) {
  indrive::testing::TempDir dir;
  const RoadNetwork net = RoadNetwork::load(indrive::testing::make_t_junction_net(dir.path()));
  SumoConfig config;
  config.mode = SumoMode::kLibtraci;  // never started: spawnable() needs no simulation
  auto sumo = make_sumo_connection(config);
  TrafficManager traffic(*sumo, net, {}, TrafficConfig{});
  const Pose2 ego{100.0, -1.75, 0.0};                         // heading east
  EXPECT_FALSE(traffic.spawnable(ego, {120.0, -1.75, 0.0}));  // 20 m straight ahead: in view
  EXPECT_FALSE(traffic.spawnable(ego, {125.0, 10.0, 0.0}));   // 27 m ahead-left, in the cone
  EXPECT_TRUE(traffic.spawnable(ego, {140.0, -1.75, 0.0}));   // 40 m ahead: beyond 30 m
  EXPECT_TRUE(traffic.spawnable(ego, {80.0, -1.75, 0.0}));    // 20 m behind
  EXPECT_TRUE(traffic.spawnable(ego, {105.0, 20.0, 0.0}));    // beside, outside the cone
  EXPECT_FALSE(traffic.spawnable(ego, {92.0, 1.75, 0.0}));    // 8 m away: too close
  EXPECT_FALSE(traffic.spawnable(ego, {100.0 - 151.0, -1.75, 0.0}));  // beyond 150 m
}

}  // namespace
}  // namespace indrive::env
