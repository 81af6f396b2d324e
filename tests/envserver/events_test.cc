#include "indrive/envserver/events.h"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <vector>

#include "sim_test_net.h"
#include "testing.h"

namespace indrive::env {
namespace {

constexpr double kPi = std::numbers::pi;

TEST(BoxesOverlap, SeparatedTouchingAndRotatedCases) {
  const Box a{SemanticClass::kVehicle, {0.0, 0.0, 0.0}, 4.0, 2.0, 1.5};
  Box b = a;
  b.pose.x_m = 4.1;  // 0.1 m gap nose to tail
  EXPECT_FALSE(boxes_overlap(a, b));
  b.pose.x_m = 3.9;  // 0.1 m overlap
  EXPECT_TRUE(boxes_overlap(a, b));
  b.pose = {0.0, 2.05, 0.0};  // side by side, 5 cm apart
  EXPECT_FALSE(boxes_overlap(a, b));
  // A square rotated 45 deg: its corner reaches sqrt(2) from its centre. Placed diagonally off
  // a's corner (2, 1) so the axis-aligned bounding boxes overlap but the shapes do not.
  const Box diamond{SemanticClass::kVehicle, {2.0 + 1.2, 1.0 + 1.2, kPi / 4}, 2.0, 2.0, 1.5};
  EXPECT_FALSE(boxes_overlap(a, diamond));
  // Moved so its corner (pointing along -x) pokes 0.2 m into a's right end.
  const Box poke{
      SemanticClass::kVehicle, {2.0 + std::sqrt(2.0) - 0.2, 0.0, kPi / 4}, 2.0, 2.0, 1.5};
  EXPECT_TRUE(boxes_overlap(a, poke));
  EXPECT_TRUE(boxes_overlap(poke, a));
}

TEST(EventNames, JoinSetBits) {
  EXPECT_EQ(event_names(0), "none");
  EXPECT_EQ(event_names(kCollision | kStall), "collision+stall");
  EXPECT_TRUE(is_terminal(kDestination));
  EXPECT_FALSE(is_failure(kDestination));
  EXPECT_FALSE(is_terminal(kTimeLimit));
  EXPECT_TRUE(is_failure(kTimeLimit));
  EXPECT_TRUE(is_terminal(kTimeLimit | kCollision));
  EXPECT_EQ(event_names(kOffRoad | kOffRoute), "off_road+off_route");
  EXPECT_EQ(event_names(kOutOfLane | kTooSlow), "out_of_lane+too_slow");
  EXPECT_TRUE(is_failure(kOutOfLane) && is_terminal(kOutOfLane));
  EXPECT_TRUE(is_failure(kTooSlow) && is_terminal(kTooSlow));
  EXPECT_TRUE(is_failure(kOffRoute));
  EXPECT_TRUE(is_terminal(kOffRoute));
  // Every bit below kNumEvents has a name.
  for (int i = 0; i < kNumEvents; ++i) {
    EXPECT_STRNE(event_name(static_cast<EventBit>(1u << i)), "unknown") << i;
  }
  EXPECT_STREQ(event_name(static_cast<EventBit>(1u << kNumEvents)), "unknown");
}

// The T-junction test network: eastbound lane "we_0" centre at y = -1.75 from x ~ 0 to the
// junction at x = 150, width 3.5 m.
class EventDetectorTest : public ::testing::Test {
 protected:
  void SetUp() override {
    net_ = std::make_unique<RoadNetwork>(
        RoadNetwork::load(indrive::testing::make_t_junction_net(dir_.path())));
    detector_ = std::make_unique<EventDetector>(*net_, EventConfig{}, EgoParams{});
    detector_->reset();
  }
  std::uint32_t check(const Pose2& pose, double speed = 5.0, std::span<const Box> others = {},
                      int step = 1) {
    return detector_->update(
        {.ego = {.pose = pose, .speed_mps = speed}, .others = others, .step = step});
  }

  indrive::testing::TempDir dir_;
  std::unique_ptr<RoadNetwork> net_;
  std::unique_ptr<EventDetector> detector_;
};

TEST_F(EventDetectorTest, CleanDriveAlongTheLaneFiresNothing) {
  for (int i = 0; i < 200; ++i) {
    const double x = 10.0 + 0.5 * i;  // 10 m .. 110 m, lane centre, heading east
    ASSERT_EQ(check({x, -1.75, 0.0}, 5.0, {}, i + 1), 0u) << "at x = " << x;
  }
  // Through the junction and up the north branch, on its northbound lane (x = 151.75).
  for (double y = -1.75; y < 60.0; y += 0.5) {
    ASSERT_EQ(check({151.75, y, kPi / 2}), 0u) << "at y = " << y;
  }
}

TEST_F(EventDetectorTest, LaneInvasionWhenMoreThanThirtyCentimetresCrossTheMarking) {
  // Lane half width 1.75, car half width 1.05: overlap beyond the marking = |lat| - 0.7.
  EXPECT_EQ(check({60.0, -1.75 + 0.95, 0.0}), 0u);             // 0.25 m over the centre line
  EXPECT_EQ(check({60.0, -1.75 + 1.05, 0.0}), kLaneInvasion);  // 0.35 m over
  // Towards the road edge too.
  EXPECT_EQ(check({60.0, -1.75 - 1.05, 0.0}), kLaneInvasion);
}

TEST_F(EventDetectorTest, WrongDirectionWhenFacingAgainstTheLane) {
  EXPECT_EQ(check({60.0, -1.75, kPi * 0.45}), 0u);  // 81 deg off: still allowed
  // On the westbound lane (y = +1.75) facing east: wrong way, and no lane invasion since it
  // sits centred in that lane.
  EXPECT_EQ(check({60.0, 1.75, 0.0}), kWrongDirection);
  EXPECT_EQ(check({60.0, -1.75, kPi}), kWrongDirection);
}

TEST_F(EventDetectorTest, OffRoadOutsideEveryLaneAndJunction) {
  const std::uint32_t bits = check({60.0, -12.0, 0.0});
  EXPECT_TRUE(bits & kOffRoad) << event_names(bits);
  EXPECT_FALSE(check({60.0, -1.75, 0.0}) & kOffRoad);
  // Inside the junction, crooked: neither off road nor a lane rule.
  EXPECT_EQ(check({150.0, 0.0, kPi / 4}), 0u);
}

TEST_F(EventDetectorTest, CollisionOnlyFromBoxOverlap) {
  const std::vector<Box> ahead = {
      {SemanticClass::kVehicle, {60.0 + 4.7, -1.75, 0.0}, 4.8, 2.1, 1.5}};
  EXPECT_EQ(check({60.0, -1.75, 0.0}, 5.0, ahead), kCollision);
  const std::vector<Box> gap = {{SemanticClass::kVehicle, {60.0 + 4.9, -1.75, 0.0}, 4.8, 2.1, 1.5}};
  EXPECT_EQ(check({60.0, -1.75, 0.0}, 5.0, gap), 0u);
  // SUMO's report without contact (its junction check on the mirrored ego) is no event, only
  // a diagnostic; with contact the event fires and the diagnostic stays off.
  EXPECT_EQ(detector_->update({.ego = {.pose = {60.0, -1.75, 0.0}, .speed_mps = 5.0},
                               .others = gap,
                               .sumo_collision = true,
                               .step = 1}),
            0u);
  EXPECT_TRUE(detector_->sumo_only_collision());
  EXPECT_EQ(detector_->update({.ego = {.pose = {60.0, -1.75, 0.0}, .speed_mps = 5.0},
                               .others = ahead,
                               .sumo_collision = true,
                               .step = 2}),
            kCollision);
  EXPECT_FALSE(detector_->sumo_only_collision());
  // A side impact: a crossing car's corner inside the ego's flank.
  const std::vector<Box> side = {
      {SemanticClass::kVehicle, {60.0 + 1.0, -1.75 + 2.5, kPi / 2}, 4.8, 2.1, 1.5}};
  EXPECT_EQ(check({60.0, -1.75, 0.0}, 5.0, side), kCollision);
}

TEST_F(EventDetectorTest, StallAfterSixtySecondsBelowOneKilometrePerHour) {
  for (int i = 1; i < 600; ++i) ASSERT_EQ(check({60.0, -1.75, 0.0}, 0.2, {}, i), 0u) << i;
  EXPECT_EQ(check({60.0, -1.75, 0.0}, 0.2, {}, 600), kStall);
  // Moving again restarts the timer.
  detector_->reset();
  for (int i = 1; i < 400; ++i) check({60.0, -1.75, 0.0}, 0.0, {}, i);
  check({60.0, -1.75, 0.0}, 1.0, {}, 400);
  for (int i = 401; i < 900; ++i) ASSERT_EQ(check({60.0, -1.75, 0.0}, 0.0, {}, i), 0u) << i;
}

TEST_F(EventDetectorTest, DestinationAndTimeLimit) {
  EXPECT_EQ(detector_->update({.ego = {.pose = {60.0, -1.75, 0.0}, .speed_mps = 5.0},
                               .route_finished = true,
                               .step = 10}),
            kDestination);
  EXPECT_EQ(check({60.0, -1.75, 0.0}, 5.0, {}, 999), 0u);
  EXPECT_EQ(check({60.0, -1.75, 0.0}, 5.0, {}, 1000), kTimeLimit);
}

// Off the route: the route "north" turns left at the junction (we -> cn).
class OffRouteTest : public EventDetectorTest {
 protected:
  void SetUp() override {
    EventDetectorTest::SetUp();
    route_ = std::make_unique<Route>(*net_, RouteSpec{"north", false, {"we", "cn"}});
    tracker_ = std::make_unique<RouteTracker>(*route_);
  }
  // One step at `pose`, the route tracker's distance passed on as the env does.
  std::uint32_t drive(const Pose2& pose) {
    const RouteStep at = tracker_->update(pose);
    return detector_->update({.ego = {.pose = pose, .speed_mps = 5.0},
                              .route_distance_m = at.distance_to_route_m,
                              .step = ++step_});
  }
  std::unique_ptr<Route> route_;
  std::unique_ptr<RouteTracker> tracker_;
  int step_ = 0;
};

TEST_F(OffRouteTest, StayingOnTheRouteThroughItsTurnNeverFires) {
  detector_->reset(route_.get());
  int junction_steps = 0;
  for (double s = 0.0; s <= route_->length_m(); s += 0.5) {
    ASSERT_EQ(drive(route_->pose_at(s)), 0u) << "at s = " << s;
    junction_steps += detector_->road().in_junction;
  }
  EXPECT_GT(junction_steps, 10);  // the left turn on the junction's internal lanes
}

TEST_F(OffRouteTest, GoingStraightWhereTheRouteTurnsFiresOnTheFirstLaneAfter) {
  detector_->reset(route_.get());
  double fired_at = -1.0;
  // From the route's start (the tracker follows the ego step by step, as in the env).
  for (double x = route_->start_pose().x_m; x < 220.0; x += 0.5) {
    const std::uint32_t bits = drive({x, -1.75, 0.0});
    if (bits == 0) continue;
    EXPECT_EQ(bits, kOffRoute) << event_names(bits) << " at x = " << x;
    EXPECT_FALSE(detector_->road().in_junction);
    EXPECT_EQ(net_->edge(net_->lane(detector_->road().lane).edge).id, "ce");
    fired_at = x;
    break;
  }
  EXPECT_GT(fired_at, 150.0);  // not before the junction ...
  EXPECT_LT(fired_at, 165.0);  // ... but at once after it
}

TEST_F(OffRouteTest, WithoutARouteItNeverFires) {
  detector_->reset();  // pretraining: random spawn, no route
  for (double x = 100.0; x < 220.0; x += 0.5) {
    ASSERT_EQ(check({x, -1.75, 0.0}), 0u) << "at x = " << x;
  }
}

TEST_F(OffRouteTest, FartherThanALaneWidthPlusMarginFromTheRouteFires) {
  detector_->reset(route_.get());
  const Pose2 on{60.0, -1.75, 0.0};
  auto at_distance = [&](double d) {
    return detector_->update(
        {.ego = {.pose = on, .speed_mps = 5.0}, .route_distance_m = d, .step = 1});
  };
  EXPECT_EQ(at_distance(3.5 + 0.9), 0u);  // lane width 3.5 m + margin 1 m
  EXPECT_EQ(at_distance(3.5 + 1.1), kOffRoute);
}

// The public InDRiVE code's rules (EventRules::kIndriveCode) on the same network.
class IndriveCodeRulesTest : public EventDetectorTest {
 protected:
  void SetUp() override {
    EventDetectorTest::SetUp();
    EventConfig config;
    config.rules = EventRules::kIndriveCode;
    config.time_limit_steps = 30000;
    detector_ = std::make_unique<EventDetector>(*net_, config, EgoParams{});
    route_ = std::make_unique<Route>(*net_, RouteSpec{.name = "east",
                                                      .start = Eigen::Vector2d(20.0, -1.75),
                                                      .end = Eigen::Vector2d(120.0, -1.75)});
    detector_->reset(route_.get());
  }
  std::unique_ptr<Route> route_;
};

TEST_F(IndriveCodeRulesTest, OutOfLaneBeyondFortyFivePercentOfTheNearestLanesWidth) {
  // Lane width 3.5 m: out of lane beyond 1.575 m from the nearest lane's centre line.
  EXPECT_EQ(check({60.0, -1.75 + 1.5, 0.0}), 0u);
  EXPECT_EQ(check({60.0, -1.75 - 1.65, 0.0}), kOutOfLane);
  // Half way between the two lanes of the road (on the centre line) the nearest lane is 1.75 m
  // away: out of lane, though both lanes are under the car.
  EXPECT_EQ(check({60.0, 0.0, 0.0}), kOutOfLane);
  // Centred in the other direction's lane: in a lane, and wrong-way driving ends nothing yet.
  EXPECT_EQ(check({60.0, 1.75, 0.0}), 0u);
  // Far off: off road and out of lane.
  EXPECT_EQ(check({60.0, -12.0, 0.0}), kOutOfLane | kOffRoad);
}

TEST_F(IndriveCodeRulesTest, LaneInvasionsAreCountedNotTerminal) {
  // Over the marking by 0.35 m (the strict rule's invasion) but within 45% of the lane width.
  for (int i = 1; i <= 3; ++i) {
    EXPECT_EQ(check({60.0, -1.75 + 1.05, 0.0}, 5.0, {}, 2 * i - 1), 0u);
    EXPECT_EQ(check({60.0, -1.75, 0.0}, 5.0, {}, 2 * i), 0u);
  }
  EXPECT_EQ(detector_->lane_invasions(), 3);
  detector_->reset(route_.get());
  EXPECT_EQ(detector_->lane_invasions(), 0);
}

TEST_F(IndriveCodeRulesTest,
       WrongDirectionAfterTwoThousandStepsAgainstTheLaneAboveHalfAMetrePerSecond) {
  const Pose2 against{60.0, 1.75, 0.0};  // westbound lane, facing east
  for (int i = 1; i < 2000; ++i) ASSERT_EQ(check(against, 1.0, {}, i), 0u) << i;
  EXPECT_EQ(check(against, 1.0, {}, 2000), kWrongDirection);
  // Slower than 0.5 m/s does not count, and breaks the run.
  detector_->reset(route_.get());
  for (int i = 1; i < 1500; ++i) check(against, 1.0, {}, i);
  check(against, 0.4, {}, 1500);
  for (int i = 1501; i < 3000; ++i) ASSERT_EQ(check(against, 1.0, {}, i), 0u) << i;
  // 110 deg off the lane is not wrong direction (the code's 120 deg).
  detector_->reset(route_.get());
  for (int i = 1; i <= 2500; ++i) {
    ASSERT_EQ(check({60.0, -1.75, kPi * 110.0 / 180.0}, 1.0, {}, i), 0u) << i;
  }
}

TEST_F(IndriveCodeRulesTest, TooSlowForTwoThousandStepsAfterTheFirstTwoThousand) {
  const Pose2 still{60.0, -1.75, 0.0};
  // Standing for the first 2,000 steps is the grace; 2,000 more end the episode.
  for (int i = 1; i < 4000; ++i) ASSERT_EQ(check(still, 0.0, {}, i), 0u) << i;
  EXPECT_EQ(check(still, 0.0, {}, 4000), kTooSlow);
  // The strict stall (60 s) never applies.
  detector_->reset(route_.get());
  for (int i = 2001; i < 3000; ++i) ASSERT_EQ(check(still, 0.005, {}, i), 0u) << i;
  check(still, 0.02, {}, 3000);
  for (int i = 3001; i < 5000; ++i) ASSERT_EQ(check(still, 0.0, {}, i), 0u) << i;
  EXPECT_EQ(check(still, 0.0, {}, 5000), kTooSlow);
}

TEST_F(IndriveCodeRulesTest, SuccessWithinTwoMetresOfTheEndPointByAnyPath) {
  EXPECT_EQ(check({117.9, -1.75, 0.0}), 0u);
  EXPECT_EQ(check({118.1, -1.75, 0.0}), kDestination);
  // The tracker's report counts for nothing here; the distance does.
  EXPECT_EQ(detector_->update({.ego = {.pose = {60.0, -1.75, 0.0}, .speed_mps = 5.0},
                               .route_finished = true,
                               .step = 10}),
            0u);
  // Neither leaving the route nor the strict lane rules end an episode.
  EXPECT_EQ(check({151.75, 30.0, kPi / 2}), 0u);
  EXPECT_EQ(check({60.0, -1.75, 0.0}, 5.0, {}, 29999), 0u);
  EXPECT_EQ(check({60.0, -1.75, 0.0}, 5.0, {}, 30000), kTimeLimit);
}

}  // namespace
}  // namespace indrive::env
