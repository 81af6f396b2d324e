// Task rewards against values computed by hand from the formula in reward.h.
#include "indrive/envserver/reward.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>

namespace indrive::env {
namespace {

TEST(RewardTest, WeightTablesMatchThePaper) {
  const RewardWeights lf = reward_weights("lane_following");
  EXPECT_EQ(lf.waypoint, 1.0);
  EXPECT_EQ(lf.target_speed_mps, 5.0);
  EXPECT_EQ(lf.speed_scale, 0.05);
  EXPECT_EQ(lf.lane, 2.0);
  EXPECT_EQ(lf.collision, 30.0);
  EXPECT_EQ(lf.destination, 100.0);
  EXPECT_EQ(lf.time, 0.01);
  const RewardWeights ca = reward_weights("collision_avoidance");
  EXPECT_EQ(ca.waypoint, 0.5);
  EXPECT_EQ(ca.target_speed_mps, 3.0);
  EXPECT_EQ(ca.speed_scale, 0.03);
  EXPECT_EQ(ca.lane, 1.0);
  EXPECT_EQ(ca.collision, 80.0);
  EXPECT_EQ(ca.destination, 100.0);
  EXPECT_EQ(ca.time, 0.01);
  try {
    reward_weights("parking");
    FAIL() << "expected std::invalid_argument";
  } catch (const std::invalid_argument& error) {
    EXPECT_THAT(error.what(), ::testing::HasSubstr("lane_following, collision_avoidance"));
  }
}

TEST(RewardTest, SpeedTrackingAlongTheWaypointHeading) {
  const RewardWeights lf = lane_following_weights();
  // At v* straight along the route: 0.05 * 5 = 0.25.
  EXPECT_NEAR(speed_reward(lf, {5.0, 0.0}, 0.0), 0.25, 1e-12);
  // Standing still: 0.05 * (5 - 5) = 0.
  EXPECT_NEAR(speed_reward(lf, {0.0, 0.0}, 0.0), 0.0, 1e-12);
  // 7 m/s is 2 over: 0.05 * (5 - 2) = 0.15.
  EXPECT_NEAR(speed_reward(lf, {7.0, 0.0}, 0.0), 0.15, 1e-12);
  // Heading north at 3 m/s with 0.3 m/s sideways: 0.05 * (5 - 2 - 2 * 0.3) = 0.12.
  EXPECT_NEAR(speed_reward(lf, {0.3, 3.0}, M_PI / 2), 0.12, 1e-12);
  // The lateral part is capped at 0.5 m/s: 4 m/s along, 2 m/s across ->
  // 0.05 * (5 - 1 - 2 * 0.5) = 0.15.
  EXPECT_NEAR(speed_reward(lf, {-2.0, 4.0}, M_PI / 2), 0.15, 1e-12);
  // Driving backwards against the route at 2 m/s: 0.05 * (5 - 7) = -0.1.
  EXPECT_NEAR(speed_reward(lf, {-2.0, 0.0}, 0.0), -0.1, 1e-12);
  const RewardWeights ca = collision_avoidance_weights();
  // CA at 3 m/s along the route: 0.03 * 3 = 0.09.
  EXPECT_NEAR(speed_reward(ca, {0.0, -3.0}, -M_PI / 2), 0.09, 1e-12);
}

TEST(RewardTest, LaneKeepingBandThenQuadratic) {
  const RewardWeights lf = lane_following_weights();
  // Lane 3.5 m: free band 0.7 m, full penalty at 1.75 m.
  EXPECT_EQ(lane_reward(lf, 0.0, 3.5), 0.0);
  EXPECT_EQ(lane_reward(lf, -0.7, 3.5), 0.0);
  // 1.225 m is half way from 0.7 to 1.75: -2 * 0.5^2 = -0.5.
  EXPECT_NEAR(lane_reward(lf, 1.225, 3.5), -0.5, 1e-12);
  EXPECT_NEAR(lane_reward(lf, -1.225, 3.5), -0.5, 1e-12);
  EXPECT_NEAR(lane_reward(lf, 1.75, 3.5), -2.0, 1e-12);
  // Saturates beyond half a lane.
  EXPECT_NEAR(lane_reward(lf, 4.0, 3.5), -2.0, 1e-12);
  // CA weight 1, lane 3 m: band 0.6, span 0.9; d = 0.9 -> -(0.3 / 0.9)^2 = -1/9.
  EXPECT_NEAR(lane_reward(collision_avoidance_weights(), 0.9, 3.0), -1.0 / 9.0, 1e-12);
}

TEST(RewardTest, CollisionProportionalToSpeed) {
  const RewardWeights lf = lane_following_weights();
  EXPECT_NEAR(collision_reward(lf, 5.0), -30.0, 1e-12);   // at v*
  EXPECT_NEAR(collision_reward(lf, 2.5), -15.0, 1e-12);   // half of v*
  EXPECT_NEAR(collision_reward(lf, 10.0), -60.0, 1e-12);  // twice v*
  EXPECT_NEAR(collision_reward(lf, 0.0), -6.0, 1e-12);    // floor: 0.2 of the weight
  EXPECT_NEAR(collision_reward(collision_avoidance_weights(), 3.0), -80.0, 1e-12);
}

TEST(RewardTest, AllTermsOfOneStep) {
  RewardInputs inputs;
  inputs.waypoints_passed = 2;
  inputs.velocity_mps = {4.0, 0.0};
  inputs.next_waypoint_heading_rad = 0.0;
  inputs.lateral_offset_m = 1.225;
  inputs.lane_width_m = 3.5;
  RewardTerms terms = compute_reward(lane_following_weights(), inputs);
  EXPECT_NEAR(terms.waypoint, 2.0, 1e-12);
  EXPECT_NEAR(terms.speed, 0.05 * (5.0 - 1.0), 1e-12);
  EXPECT_NEAR(terms.lane, -0.5, 1e-12);
  EXPECT_EQ(terms.collision, 0.0);
  EXPECT_EQ(terms.destination, 0.0);
  EXPECT_NEAR(terms.time, -0.01, 1e-12);
  EXPECT_NEAR(terms.total(), 2.0 + 0.2 - 0.5 - 0.01, 1e-12);

  // A collision at 4 m/s on the step the destination is reached, CA weights.
  inputs.collision = true;
  inputs.destination_reached = true;
  inputs.waypoints_passed = -3;  // never negative
  terms = compute_reward(collision_avoidance_weights(), inputs);
  EXPECT_EQ(terms.waypoint, 0.0);
  EXPECT_NEAR(terms.collision, -80.0 * 4.0 / 3.0, 1e-12);
  EXPECT_EQ(terms.destination, 100.0);
  // Lane: band 0.7, span 1.05; (0.525 / 1.05)^2 = 0.25 with weight 1.
  EXPECT_NEAR(terms.lane, -0.25, 1e-12);
  EXPECT_NEAR(terms.speed, 0.03 * (3.0 - 1.0), 1e-12);
}

}  // namespace
}  // namespace indrive::env
