// Routes: the built-in routes of both towns are valid, the tracker measures progress, and bad
// specs are rejected with a clear message.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>
#include <set>

#include "indrive/envserver/net_geometry.h"
#include "net_test_network.h"
#include "net_test_town.h"

namespace indrive::env {
namespace {

using ::testing::HasSubstr;

struct RouteCase {
  std::string town;
  std::string route;
};

void PrintTo(const RouteCase& c, std::ostream* os) { *os << c.town << "/" << c.route; }

std::string case_name(const ::testing::TestParamInfo<RouteCase>& info) {
  return info.param.town + "_" + info.param.route;
}

std::vector<RouteCase> all_cases() {
  std::vector<RouteCase> cases;
  for (const std::string town : {"town01", "town02"}) {
    for (const auto name : kRouteNames) cases.push_back({town, std::string(name)});
  }
  return cases;
}

class BuiltInRouteTest : public ::testing::TestWithParam<RouteCase> {
 protected:
  const Town& town() const { return testing::cached_town(GetParam().town); }
  const Route& route() const { return find_route(town().routes, GetParam().route); }
};

TEST_P(BuiltInRouteTest, LanesAreConnectedEndToEnd) {
  const RoadNetwork& net = town().net;
  const std::vector<int>& lanes = route().lanes();
  ASSERT_GE(lanes.size(), 3u);
  const size_t joints = route().is_loop() ? lanes.size() : lanes.size() - 1;
  for (size_t k = 0; k < joints; ++k) {
    const Lane& a = net.lane(lanes[k]);
    const Lane& b = net.lane(lanes[(k + 1) % lanes.size()]);
    EXPECT_LT((a.shape.back() - b.shape.front()).norm(), 0.05) << a.id << " -> " << b.id;
    // Normal and internal lanes alternate through every junction.
    EXPECT_TRUE(a.internal || b.internal) << a.id << " -> " << b.id;
  }
}

TEST_P(BuiltInRouteTest, TurnDirectionsMatchTheRouteKind) {
  const std::vector<TurnDirection>& turns = route().turns();
  const std::string& name = GetParam().route;
  int rights = 0;
  int lefts = 0;
  for (TurnDirection turn : turns) {
    rights += is_right_turn(turn);
    lefts += is_left_turn(turn);
    EXPECT_NE(turn, TurnDirection::kTurnaround);
  }
  if (name == "straight") {
    EXPECT_FALSE(route().is_loop());
    EXPECT_EQ(rights + lefts, 0);
    EXPECT_GE(turns.size(), 1u);  // it does cross junctions, straight through
  } else {
    EXPECT_TRUE(route().is_loop());
    EXPECT_EQ(turns.size(), route().spec().edges.size());  // the closing junction included
  }
  if (name == "right_loop") {
    EXPECT_GE(rights, 3);
    EXPECT_EQ(lefts, 0);
  }
  if (name == "left_loop") {
    EXPECT_GE(lefts, 3);
    EXPECT_EQ(rights, 0);
  }
  if (name == "two_turn") {
    EXPECT_GE(rights, 1);
    EXPECT_GE(lefts, 1);
  }
}

TEST_P(BuiltInRouteTest, WaypointsAreDenseSmoothAndOnTheRoute) {
  const RoadNetwork& net = town().net;
  const std::vector<Waypoint>& waypoints = route().waypoints();
  const std::set<int> lanes(route().lanes().begin(), route().lanes().end());
  ASSERT_GE(static_cast<double>(waypoints.size()), route().length_m() / 2.0 - 1.0);  // ~2 m
  ASSERT_GT(waypoints.size(), 40u);
  for (size_t i = 0; i < waypoints.size(); ++i) {
    const Waypoint& w = waypoints[i];
    const auto at = net.locate(w.position, w.heading_rad);
    ASSERT_TRUE(at.has_value()) << "waypoint " << i << " is off the road";
    EXPECT_TRUE(lanes.count(at->lane)) << "waypoint " << i << " on " << net.lane(at->lane).id;
    EXPECT_LT(std::abs(at->lateral_m), 0.1) << "waypoint " << i;
    EXPECT_DOUBLE_EQ(w.lane_width_m, 3.5);
    if (i + 1 < waypoints.size()) {
      const Waypoint& next = waypoints[i + 1];
      EXPECT_NEAR((next.position - w.position).norm(), 2.0, 0.15) << i;
      EXPECT_LT(std::abs(wrap_angle(next.heading_rad - w.heading_rad)), 0.5) << i;
    }
  }
  if (route().is_loop()) {
    // The loop closes: from the last waypoint one more step reaches the first.
    EXPECT_NEAR((waypoints.front().position - waypoints.back().position).norm(), 2.0, 0.15);
    // Clockwise (negative area) for right turns, counter-clockwise for left turns.
    std::vector<Eigen::Vector2d> polygon;
    for (const Waypoint& w : waypoints) polygon.push_back(w.position);
    const double area = geometry::signed_area(polygon);
    if (GetParam().route == "right_loop") {
      EXPECT_LT(area, -1000.0);
    }
    if (GetParam().route == "left_loop") {
      EXPECT_GT(area, 1000.0);
    }
  } else {
    // The straight corridor never bends.
    for (const Waypoint& w : waypoints) {
      EXPECT_LT(std::abs(wrap_angle(w.heading_rad - waypoints.front().heading_rad)), 0.05);
    }
  }
  const Pose2 start = route().start_pose();
  EXPECT_NEAR(start.x_m, waypoints.front().position.x(), 1e-9);
  EXPECT_NEAR(start.yaw_rad, waypoints.front().heading_rad, 1e-9);
}

TEST_P(BuiltInRouteTest, TrackerCountsEveryWaypointOnceAndFinishes) {
  const Route& r = route();
  RouteTracker tracker(r);
  int passed = 0;
  bool finished_early = false;
  RouteStep step;
  // Drive the centre line 0.5 m per step, 0.4 m left of it, to the end of a corridor or half
  // a metre into a loop's second lap.
  const double end = r.is_loop() ? r.length_m() + 0.5 : r.length_m();
  std::vector<double> stations;
  for (double s = 0.5; s < end; s += 0.5) stations.push_back(s);
  stations.push_back(end);
  for (double s : stations) {
    const Pose2 on = r.pose_at(s);
    const Pose2 pose{on.x_m - 0.4 * std::sin(on.yaw_rad), on.y_m + 0.4 * std::cos(on.yaw_rad),
                     on.yaw_rad};
    step = tracker.update(pose);
    EXPECT_GE(step.waypoints_passed, 0);
    passed += step.waypoints_passed;
    const double radius = r.is_loop() ? kLapToleranceM : kDestinationRadiusM;
    if (step.finished && s < r.length_m() - radius - 0.5) finished_early = true;
    EXPECT_NEAR(step.lateral_m, 0.4, 0.05) << "s = " << s;
  }
  EXPECT_FALSE(finished_early);
  EXPECT_TRUE(step.finished);
  EXPECT_NEAR(step.progress_m, end, 0.05);
  // A loop passes all its waypoints (the first again at the end); a corridor all but the
  // first, where it starts.
  const int expected = static_cast<int>(r.waypoints().size()) - (r.is_loop() ? 0 : 1);
  EXPECT_EQ(passed, expected);
}

// The shipped loops turn as their route files say; going straight through a T-junction is
// kStraight, no turn. town01's right_loop goes straight through M2 as `straight` does.
TEST(BuiltInRouteTurnsTest, LoopsTurnAsTheRouteFilesSay) {
  using T = TurnDirection;
  auto turns = [](const std::string& town, const std::string& name) {
    return find_route(testing::cached_town(town).routes, name).turns();
  };
  const T r = T::kRight;
  const T l = T::kLeft;
  const T s = T::kStraight;
  EXPECT_EQ(turns("town01", "right_loop"), (std::vector<T>{r, r, r, s, r}));
  EXPECT_EQ(turns("town01", "left_loop"), (std::vector<T>{s, l, l, l, l}));
  EXPECT_EQ(turns("town02", "two_turn"), (std::vector<T>{r, l, s, r, s, r}));
  for (const std::string town : {"town01", "town02"}) {
    for (T turn : turns(town, "right_loop")) EXPECT_TRUE(turn == r || turn == s) << town;
    for (T turn : turns(town, "left_loop")) EXPECT_TRUE(turn == l || turn == s) << town;
  }
}

INSTANTIATE_TEST_SUITE_P(Towns, BuiltInRouteTest, ::testing::ValuesIn(all_cases()), case_name);

class HandRouteTest : public ::testing::Test {
 protected:
  HandRouteTest() : net_(RoadNetwork::parse(testing::kHandNetwork, "hand")) {}
  RoadNetwork net_;
};

TEST_F(HandRouteTest, RouteThroughAJunction) {
  const Route route(net_, RouteSpec{"east", false, {"ab", "bd"}});
  EXPECT_EQ(route.lanes(), (std::vector<int>{net_.find_lane("ab_0"), net_.find_lane(":b_0_0"),
                                             net_.find_lane("bd_0")}));
  EXPECT_EQ(route.turns(), std::vector<TurnDirection>{TurnDirection::kStraight});
  // The lanes end at x = 150; the route is set back by half its 40 m last edge (less than
  // kRouteEndSetbackM) and ends at x = 130.
  EXPECT_NEAR(route.length_m(), 130.0, 1e-9);
  ASSERT_EQ(route.waypoints().size(), 66u);  // 0, 2, ..., 130
  EXPECT_NEAR(route.waypoints()[10].position.x(), 20.0, 1e-9);
  EXPECT_NEAR(route.waypoints().back().position.x(), 130.0, 1e-9);
  // 0.5 m north of x = 60: left of the eastbound route.
  const RoutePoint at = route.project({60.0, -1.25});
  EXPECT_NEAR(at.s_m, 60.0, 1e-9);
  EXPECT_NEAR(at.lateral_m, 0.5, 1e-9);
  EXPECT_NEAR(at.heading_rad, 0.0, 1e-9);
  // A window around s = 10 only sees s in [0, 20].
  EXPECT_NEAR(route.project({60.0, -1.25}, 10.0, 10.0).s_m, 20.0, 1e-9);
  EXPECT_EQ(route.next_waypoint(59.0), 30);
  EXPECT_EQ(route.next_waypoint(60.0), 31);
  EXPECT_EQ(route.next_waypoint(200.0), 65);
}

TEST_F(HandRouteTest, DestinationWithinTenMetresOfTheTerminalWaypoint) {
  const Route route(net_, RouteSpec{"east", false, {"ab", "bd"}});
  const double end_x = route.waypoints().back().position.x();  // 130
  RouteTracker tracker(route);
  // Eastbound on the lane centre up to 11 m before the end: not reached.
  for (double x = 1.0; x <= end_x - 11.0 + 1e-9; x += 0.5) {
    ASSERT_FALSE(tracker.update({x, -1.75, 0.0}).finished) << "x = " << x;
  }
  // 9.5 m along the route but 9 m to the side: farther than the radius in a straight line.
  EXPECT_FALSE(tracker.update({end_x - 9.5, -1.75 + 9.0, 0.0}).finished);
  EXPECT_TRUE(tracker.update({end_x - 9.5, -1.75, 0.0}).finished);
  EXPECT_TRUE(tracker.update({end_x - 2.0, -1.75, 0.0}).finished);
}

TEST(RouteEndTest, TownStraightEndsBeforeTheJunctionApproach) {
  for (const std::string town : {"town01", "town02"}) {
    const Town& t = testing::cached_town(town);
    const Route& straight = find_route(t.routes, "straight");
    const Waypoint& terminal = straight.waypoints().back();
    const Lane& last = t.net.lane(straight.lanes().back());
    EXPECT_EQ(t.net.edge(last.edge).id, town == "town01" ? "B2_B3" : "M3_E1") << town;
    // The last lane ends at the stop line of the next junction (B3, E1); the terminal waypoint
    // lies on it, set back by kRouteEndSetbackM or half the lane when that is shorter (town02's
    // M3_E1 is 33 m long).
    const auto at = t.net.locate(terminal.position, terminal.heading_rad);
    ASSERT_TRUE(at.has_value());
    EXPECT_EQ(at->lane, straight.lanes().back()) << town;
    const double setback = std::min(kRouteEndSetbackM, last.length_m / 2.0);
    EXPECT_GE(last.length_m - at->s_m, setback - 0.01) << town;
    EXPECT_GE((last.shape.back() - terminal.position).norm(), setback - 0.01) << town;
    EXPECT_FALSE(t.net.in_junction(terminal.position)) << town;
    // Every point within the destination radius of it lies outside the junction too.
    for (double d = 0.0; d <= kDestinationRadiusM; d += 1.0) {
      const Pose2 p = straight.pose_at(straight.length_m() - d);
      EXPECT_FALSE(t.net.in_junction({p.x_m, p.y_m})) << town << " " << d;
    }
  }
}

TEST_F(HandRouteTest, TrackerReversingEarnsNothing) {
  const Route route(net_, RouteSpec{"east", false, {"ab", "bd"}});
  RouteTracker tracker(route);
  auto at = [](double x) { return Pose2{x, -1.75, 0.0}; };
  EXPECT_EQ(tracker.update(at(5.0)).waypoints_passed, 2);  // waypoints at 2 and 4
  const RouteStep back = tracker.update(at(1.0));
  EXPECT_NEAR(back.delta_m, -4.0, 1e-9);
  EXPECT_EQ(back.waypoints_passed, 0);
  EXPECT_EQ(tracker.update(at(5.0)).waypoints_passed, 0);  // already counted
  EXPECT_EQ(tracker.update(at(6.5)).waypoints_passed, 1);
  EXPECT_FALSE(tracker.last().finished);
  EXPECT_TRUE(tracker.update(at(20.0)).progress_m > 19.0);
  tracker.reset();
  EXPECT_EQ(tracker.last().progress_m, 0.0);
}

TEST_F(HandRouteTest, BadSpecsAreRejected) {
  auto error_of = [&](const RouteSpec& spec) -> std::string {
    try {
      Route route(net_, spec);
    } catch (const RouteError& error) {
      return error.what();
    }
    ADD_FAILURE() << "no RouteError for " << spec.name;
    return {};
  };
  EXPECT_THAT(error_of({"a", false, {"ab", "nope"}}), HasSubstr("edge 'nope' is not a drivable"));
  EXPECT_THAT(error_of({"b", false, {"ab", "ce"}}),
              HasSubstr("no connection from edge 'ab' to edge 'ce'"));
  EXPECT_THAT(error_of({"c", true, {"ab", "bd"}}),
              HasSubstr("no connection from edge 'bd' to edge 'ab'"));
  EXPECT_THAT(error_of({"d", false, {}}), HasSubstr("has no edges"));
  EXPECT_THAT(error_of({"e", false, {":b_0"}}), HasSubstr("not a drivable edge"));
}

TEST(FindRouteTest, UnknownNameListsTheKnownOnes) {
  const Town& town = testing::cached_town("town02");
  EXPECT_EQ(find_route(town.routes, "left_loop").name(), "left_loop");
  try {
    find_route(town.routes, "figure_eight");
    FAIL() << "expected RouteError";
  } catch (const RouteError& error) {
    EXPECT_THAT(error.what(), HasSubstr("unknown route 'figure_eight'"));
    EXPECT_THAT(error.what(), HasSubstr("straight, right_loop, left_loop, two_turn"));
  }
}

}  // namespace
}  // namespace indrive::env
