// Point-to-point routes: CARLA coordinates land on the lanes the public InDRiVE code's routes
// drive, the shortest path between two points takes the lane that leads to the end, and the
// route starts and ends at the points.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <optional>

#include "net_test_network.h"
#include "net_test_town.h"

namespace indrive::env {
namespace {

using ::testing::HasSubstr;

TEST(CarlaToNetworkTest, FlipsYAndAddsTheOffset) {
  const RoadNetwork net = RoadNetwork::parse(
      R"(<net><location netOffset="10.00,-5.00"/>
           <edge id="ab"><lane id="ab_0" index="0" width="3.5" shape="0,0 50,0"/></edge></net>)",
      "offset.net.xml");
  EXPECT_EQ(net.offset(), Eigen::Vector2d(10.0, -5.0));
  EXPECT_TRUE(carla_to_network(net, {113.88, 199.41}).isApprox(Eigen::Vector2d(123.88, -204.41)));
}

// A point-to-point route of a CARLA town and its kind, as the code labels it.
struct CarlaRoute {
  std::string town;
  std::string route;
};

void PrintTo(const CarlaRoute& c, std::ostream* os) { *os << c.town << "/" << c.route; }

std::vector<CarlaRoute> carla_routes() {
  std::vector<CarlaRoute> cases;
  for (const std::string town : {"carla_town01", "carla_town02"}) {
    for (const std::string& name : town_route_names(town, testing::test_town_options())) {
      cases.push_back({town, name});
    }
  }
  return cases;
}

constexpr double kPi = std::numbers::pi;

// The turns a route makes, read off its centre line, in order: +1 a left, -1 a right. A turn
// starts where the heading changes by more than 45 degrees within 12 m and ends where it
// changes by less than 10.
std::vector<int> turns_along(const Route& route) {
  const std::vector<Waypoint>& w = route.waypoints();  // about 2 m apart
  const std::size_t k = 6;
  std::vector<int> turns;
  std::optional<double> turn_start;
  for (std::size_t i = 0; i + k < w.size(); ++i) {
    const double change = std::abs(wrap_angle(w[i + k].heading_rad - w[i].heading_rad));
    if (!turn_start && change > kPi / 4) {
      turn_start = w[i].heading_rad;
    } else if (turn_start && change < kPi / 18) {
      turns.push_back(wrap_angle(w[i].heading_rad - *turn_start) > 0 ? 1 : -1);
      turn_start.reset();
    }
  }
  if (turn_start) turns.push_back(wrap_angle(w.back().heading_rad - *turn_start) > 0 ? 1 : -1);
  return turns;
}

class CarlaRouteTest : public ::testing::TestWithParam<CarlaRoute> {
 protected:
  const Town& town() const { return testing::cached_town(GetParam().town); }
  const Route& route() const { return find_route(town().routes, GetParam().route); }
};

TEST(CarlaTownTest, ShipTheCodesRoutesEachNamedByItsKind) {
  EXPECT_EQ(town_route_names("carla_town01", testing::test_town_options()),
            (std::vector<std::string>{"straight_1", "straight_2", "right_1", "right_2", "left_1",
                                      "two_turn_1"}));
  EXPECT_EQ(town_route_names("carla_town02", testing::test_town_options()),
            (std::vector<std::string>{"straight_1", "straight_2", "left_1", "left_2", "right_1",
                                      "right_2", "two_turn_1", "two_turn_2"}));
  // The route sets are designs of our towns; the CARLA towns have the code's whatever the set.
  TownOptions left = testing::test_town_options();
  left.route_set = "left";
  EXPECT_EQ(town_route_names("carla_town02", left),
            town_route_names("carla_town02", testing::test_town_options()));
}

// Each CARLA point lies on the lane its route drives there, and that lane's heading is the
// one the route's kind says: a straight route heads for its end point, and a route's turns at
// junctions are the turns its kind names.
TEST_P(CarlaRouteTest, EachPointLiesOnTheLaneItsHeadingSays) {
  const RoadNetwork& net = town().net;
  const Route& r = route();
  ASSERT_TRUE(r.spec().start && r.spec().end);
  const Eigen::Vector2d start = *r.spec().start;
  const Eigen::Vector2d end = *r.spec().end;
  for (const auto& [point, lane] :
       {std::pair{start, r.lanes().front()}, std::pair{end, r.lanes().back()}}) {
    const LanePosition at = net.project(lane, point);
    EXPECT_LT(std::abs(at.lateral_m), 0.5 * net.lane(lane).width_m)
        << "point " << point.transpose() << " is off lane " << net.lane(lane).id;
  }
  // The route starts and ends at the points' projections.
  EXPECT_LT((r.waypoints().front().position - start).norm(),
            0.5 * net.lane(r.lanes().front()).width_m);
  EXPECT_LT((r.waypoints().back().position - end).norm(), 0.5 * net.lane(r.lanes().back()).width_m);
  EXPECT_EQ(r.destination(), end);

  // The lanes run the ways the code's yaws say (CARLA yaw -> network heading -yaw).
  ASSERT_TRUE(r.spec().start_heading_rad && r.spec().end_heading_rad);
  EXPECT_LT(std::abs(wrap_angle(r.waypoints().front().heading_rad - *r.spec().start_heading_rad)),
            kPi / 6);
  EXPECT_LT(std::abs(wrap_angle(r.waypoints().back().heading_rad - *r.spec().end_heading_rad)),
            kPi / 6);

  // The CARLA towns' junctions are joined by curved connecting roads (OpenDRIVE's), so a turn
  // happens on an edge of its own and SUMO's turn directions read "straight": the turns are
  // read off the centre line instead.
  int rights = 0, lefts = 0;
  for (const int turn : turns_along(r)) (turn > 0 ? lefts : rights) += 1;
  const std::string& name = GetParam().route;
  if (name.starts_with("straight")) {
    EXPECT_EQ(rights + lefts, 0);
    // Heading for the end point, along a path barely longer than the line between them.
    const Eigen::Vector2d towards = (end - start).normalized();
    const double heading = r.waypoints().front().heading_rad;
    EXPECT_GT(towards.dot(Eigen::Vector2d(std::cos(heading), std::sin(heading))), 0.99);
    EXPECT_LT(r.length_m(), 1.05 * (end - start).norm());
  } else if (name.starts_with("right")) {
    EXPECT_EQ(rights, 1);
    EXPECT_EQ(lefts, 0);
  } else if (name.starts_with("left")) {
    EXPECT_EQ(lefts, 1);
    EXPECT_EQ(rights, 0);
  } else {
    ASSERT_TRUE(name.starts_with("two_turn")) << name;
    EXPECT_EQ(rights + lefts, 2);
  }
  // A corner or a short corridor, not a tour of the town.
  EXPECT_LT(r.length_m(), 450.0);
}

INSTANTIATE_TEST_SUITE_P(BothCarlaTowns, CarlaRouteTest, ::testing::ValuesIn(carla_routes()),
                         [](const ::testing::TestParamInfo<CarlaRoute>& info) {
                           return info.param.town + "_" + info.param.route;
                         });

// A two-way road: from (10, -1.75) on the eastbound lane to (90, -1.75) is 80 m along it; the
// westbound lane holds neither point.
class PointPathTest : public ::testing::Test {
 protected:
  PointPathTest()
      : net_(RoadNetwork::parse(R"(<net>
  <edge id="ab" from="a" to="b"><lane id="ab_0" index="0" width="3.5" shape="0,-1.75 100,-1.75"/></edge>
  <edge id="ba" from="b" to="a"><lane id="ba_0" index="0" width="3.5" shape="100,1.75 0,1.75"/></edge>
</net>)",
                                "two-way.net.xml")) {}
  RoadNetwork net_;
};

TEST_F(PointPathTest, TakesTheLaneThatLeadsToTheEnd) {
  const PointPath east = route_edges_between(net_, {10.0, -1.5}, {90.0, -1.75});
  EXPECT_EQ(east.edges, std::vector<std::string>{"ab"});
  EXPECT_NEAR(east.length_m, 80.0, 1e-9);
  EXPECT_NEAR(east.start_s_m, 10.0, 1e-9);
  const PointPath west = route_edges_between(net_, {90.0, 1.75}, {10.0, 1.75});
  EXPECT_EQ(west.edges, std::vector<std::string>{"ba"});
  const Route route(net_, RouteSpec{.name = "east",
                                    .start = Eigen::Vector2d(10.0, -1.5),
                                    .end = Eigen::Vector2d(90.0, -1.75)});
  EXPECT_NEAR(route.length_m(), 80.0, 1e-6);
  EXPECT_NEAR(route.start_pose().x_m, 10.0, 1e-9);
  EXPECT_EQ(route.destination(), Eigen::Vector2d(90.0, -1.75));
}

TEST_F(PointPathTest, RefusesPointsOffTheRoadsAndEndsBehindTheStart) {
  try {
    route_edges_between(net_, {10.0, 30.0}, {90.0, -1.75});
    FAIL() << "a point off every lane was taken";
  } catch (const RouteError& error) {
    EXPECT_THAT(error.what(), HasSubstr("start point (10.00, 30.00)"));
    EXPECT_THAT(error.what(), HasSubstr("lies on no normal lane"));
  }
  // Behind the start on its own lane, with no way round: no path.
  EXPECT_THROW(route_edges_between(net_, {90.0, -1.75}, {10.0, -1.75}), RouteError);
  // One end point only.
  RouteSpec half{.name = "half", .start = Eigen::Vector2d(10.0, -1.75)};
  try {
    const Route route(net_, half);
    FAIL() << "a route with one end point was built";
  } catch (const RouteError& error) {
    EXPECT_THAT(error.what(), HasSubstr("give both start and end"));
  }
}

}  // namespace
}  // namespace indrive::env
