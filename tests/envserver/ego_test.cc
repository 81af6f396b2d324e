#include "indrive/envserver/ego.h"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

namespace indrive::env {
namespace {

EgoState run(const EgoModel& model, EgoState state, int action, int steps) {
  for (int i = 0; i < steps; ++i) state = model.step(state, decode_action(action));
  return state;
}

TEST(EgoActions, IndexIsSteerTimesThreePlusThrottle) {
  for (int s = 0; s < 3; ++s) {
    for (int t = 0; t < 3; ++t) {
      const Control c = decode_action(encode_action(s, t));
      EXPECT_EQ(c.steer, kSteerLevels[s]);
      EXPECT_EQ(c.throttle, kThrottleLevels[t]);
    }
  }
  EXPECT_EQ(decode_action(4).steer, 0.0);
  EXPECT_EQ(decode_action(4).throttle, 0.2);
  EXPECT_EQ(decode_action(2).steer, -0.3);
  EXPECT_EQ(decode_action(2).throttle, 0.3);
}

TEST(EgoModel, ThrottleSettlesAtSpeedsThatReachTheTaskTargets) {
  EgoModel model;
  // 60 s of constant throttle from rest: the settle speeds bracket 3 and 5 m/s.
  const EgoState low = run(model, {}, encode_action(1, 1), 600);
  const EgoState high = run(model, {}, encode_action(1, 2), 600);
  EXPECT_NEAR(low.speed_mps, 3.5, 0.01);
  EXPECT_NEAR(high.speed_mps, 6.0, 0.01);
  EXPECT_NEAR(model.settle_speed_mps(0.2), 3.5, 1e-9);
  EXPECT_NEAR(model.settle_speed_mps(0.3), 6.0, 1e-9);
  // Driving straight east keeps the heading and the lateral position.
  EXPECT_NEAR(high.pose.y_m, 0.0, 1e-9);
  EXPECT_NEAR(high.pose.yaw_rad, 0.0, 1e-12);
  // 5 m/s is reached within a block length (under 15 s).
  EgoState s{};
  int steps = 0;
  while (s.speed_mps < 5.0 && steps < 1000) s = model.step(s, decode_action(2)), ++steps;
  EXPECT_LT(steps, 150);
}

TEST(EgoModel, ZeroThrottleCoastsToAStop) {
  EgoModel model;
  EgoState s{.speed_mps = 6.0};
  s = run(model, s, encode_action(1, 0), 10);
  EXPECT_LT(s.speed_mps, 6.0);
  EXPECT_GT(s.speed_mps, 2.0);
  s = run(model, s, encode_action(1, 0), 200);
  EXPECT_EQ(s.speed_mps, 0.0);
  // Standing still with zero throttle stays still (no creeping backwards).
  const EgoState still = run(model, EgoState{}, encode_action(1, 0), 50);
  EXPECT_EQ(still.speed_mps, 0.0);
  EXPECT_EQ(still.pose.x_m, 0.0);
}

TEST(EgoModel, PositiveSteerTurnsRightOnACircleOfAboutSevenPointSevenMetres) {
  EgoModel model;
  // Drive a circle at the throttle-0.2 settle speed, starting at speed, heading east.
  EgoState s{.speed_mps = 3.5};
  const double wheel = 0.3 * 70.0 * std::numbers::pi / 180.0;
  const double beta = -std::atan(0.5 * std::tan(wheel));  // right turn: negative slip angle
  const double radius = 1.45 / std::sin(-beta);
  EXPECT_NEAR(radius, 7.7, 0.05);
  // The centre lies a radius to the right of the velocity direction (heading + beta).
  const double cx = radius * std::sin(beta);
  const double cy = -radius * std::cos(beta);
  double max_error = 0.0;
  for (int i = 0; i < 200; ++i) {
    s = model.step(s, decode_action(encode_action(2, 1)));
    max_error =
        std::max(max_error, std::abs(std::hypot(s.pose.x_m - cx, s.pose.y_m - cy) - radius));
  }
  EXPECT_LT(max_error, 0.02);
  EXPECT_LT(s.yaw_rate_radps, 0.0);  // clockwise
  // Mirror: negative steer turns left (positive yaw rate).
  EgoState l = model.step(EgoState{.speed_mps = 3.5}, decode_action(encode_action(0, 1)));
  EXPECT_GT(l.yaw_rate_radps, 0.0);
  EXPECT_GT(l.pose.y_m, 0.0);
}

TEST(EgoModel, BoxHasTheCarSize) {
  EgoModel model;
  const Box box = model.box(Pose2{1.0, 2.0, 0.5});
  EXPECT_EQ(box.cls, SemanticClass::kVehicle);
  EXPECT_DOUBLE_EQ(box.length_m, 4.8);
  EXPECT_DOUBLE_EQ(box.width_m, 2.1);
  EXPECT_DOUBLE_EQ(box.pose.yaw_rad, 0.5);
}

}  // namespace
}  // namespace indrive::env
