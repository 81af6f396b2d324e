// Geometry queries on a hand-written network, checked against values computed by hand.
#include <gtest/gtest.h>

#include <cmath>

#include "indrive/envserver/net.h"
#include "net_test_network.h"

namespace indrive::env {
namespace {

class NetQueryTest : public ::testing::Test {
 protected:
  NetQueryTest() : net_(RoadNetwork::parse(testing::kHandNetwork, "hand")) {}
  int lane(const char* id) const {
    const int index = net_.find_lane(id);
    EXPECT_GE(index, 0) << id;
    return index;
  }
  RoadNetwork net_;
};

TEST_F(NetQueryTest, ParsesCarLanesOnly) {
  // Four normal car lanes and one internal lane; the pedestrian lane is left out.
  EXPECT_EQ(net_.lanes().size(), 5u);
  EXPECT_EQ(net_.find_lane("sw_0"), -1);
  EXPECT_TRUE(net_.lane(lane(":b_0_0")).internal);
  EXPECT_FALSE(net_.lane(lane("ab_0")).internal);
  EXPECT_DOUBLE_EQ(net_.lane(lane("ce_0")).length_m, 100.0);
  EXPECT_DOUBLE_EQ(net_.lane(lane("ce_0")).width_m, 4.0);
  // SUMO's internal junctions are not areas.
  ASSERT_EQ(net_.junctions().size(), 1u);
  EXPECT_EQ(net_.junctions()[0].shape.size(), 4u);
}

TEST_F(NetQueryTest, ConnectionsAndCrossings) {
  ASSERT_EQ(net_.connections().size(), 1u);
  const Connection& connection = net_.connections()[0];
  EXPECT_EQ(connection.from_lane, lane("ab_0"));
  EXPECT_EQ(connection.to_lane, lane("bd_0"));
  EXPECT_EQ(connection.direction, TurnDirection::kStraight);
  EXPECT_EQ(net_.crossing_lanes(connection), std::vector<int>{lane(":b_0_0")});
  EXPECT_EQ(net_.internal_successor(lane(":b_0_0")), lane("bd_0"));
  EXPECT_EQ(net_.connections_from(lane("ab_0")).size(), 1u);
  EXPECT_TRUE(net_.connections_from(lane("ba_0")).empty());
}

TEST_F(NetQueryTest, LocatesPointOnStraightLane) {
  // 0.75 m north of the eastbound centre line: left of its direction.
  const auto at = net_.locate({30.0, -1.0});
  ASSERT_TRUE(at.has_value());
  EXPECT_EQ(at->lane, lane("ab_0"));
  EXPECT_NEAR(at->s_m, 30.0, 1e-9);
  EXPECT_NEAR(at->lateral_m, 0.75, 1e-9);
  EXPECT_NEAR(at->heading_rad, 0.0, 1e-9);

  // The westbound lane runs from x = 100 to 0: s = 70 at x = 30, and south is its left.
  const auto west = net_.locate({30.0, 1.0});
  ASSERT_TRUE(west.has_value());
  EXPECT_EQ(west->lane, lane("ba_0"));
  EXPECT_NEAR(west->s_m, 70.0, 1e-9);
  EXPECT_NEAR(west->lateral_m, 0.75, 1e-9);
  EXPECT_NEAR(std::abs(west->heading_rad), M_PI, 1e-9);
}

TEST_F(NetQueryTest, HeadingPicksTheLaneOnTheCentreLine) {
  // y = 0 is the border of both directions: both contain it, the yaw decides.
  EXPECT_EQ(net_.lanes_at({30.0, 0.0}).size(), 2u);
  EXPECT_EQ(net_.locate({30.0, 0.0}, 0.0)->lane, lane("ab_0"));
  EXPECT_EQ(net_.locate({30.0, 0.0}, M_PI)->lane, lane("ba_0"));
  // Slightly south, the eastbound lane fits better, but a westbound vehicle is still matched
  // to the westbound lane when it lies on it.
  EXPECT_EQ(net_.locate({30.0, 0.2}, M_PI)->lane, lane("ba_0"));
  // A westbound vehicle fully on the eastbound lane: only the wrong-way lane is there.
  EXPECT_EQ(net_.locate({30.0, -1.75}, M_PI)->lane, lane("ab_0"));
}

// Two roads that cross without a junction (a bridge converted flat, as on CARLA's Town04): a
// vehicle driving north along one is located on it, although the other's centre line is nearer
// and its direction (89.4 degrees off) is still within 90 degrees of the vehicle's.
TEST(NetQueryCrossingTest, WhereRoadsCrossWithoutAJunctionTheRoadDrivenAlongWins) {
  const RoadNetwork net = RoadNetwork::parse(R"(<net version="1.9">
  <edge id="we" from="w" to="e"><lane id="we_0" index="0" width="3.5" shape="-50,-0.5 50,0.5"/></edge>
  <edge id="sn" from="s" to="n"><lane id="sn_0" index="0" width="3.5" shape="0,-50 0,50"/></edge>
</net>)",
                                             "crossing");
  const Eigen::Vector2d point(0.05, 0.0005);  // on we_0's centre line, 5 cm east of sn_0's
  ASSERT_EQ(net.lanes_at(point).size(), 2u);
  EXPECT_EQ(net.locate(point)->lane, net.find_lane("we_0")) << "without a heading: the nearer";
  EXPECT_EQ(net.locate(point, 0.5 * M_PI)->lane, net.find_lane("sn_0"));
  EXPECT_EQ(net.locate(point, 0.0)->lane, net.find_lane("we_0"));
  // A vehicle across both (45 degrees to each): the better fit, as before.
  EXPECT_EQ(net.locate(point, 0.25 * M_PI)->lane, net.find_lane("we_0"));
}

TEST_F(NetQueryTest, OffRoadPointsAndMargins) {
  EXPECT_FALSE(net_.locate({30.0, 5.0}).has_value());
  EXPECT_FALSE(net_.is_drivable({30.0, 5.0}));
  // Within a 2 m margin the westbound lane reaches it: 3.25 m to the right of its centre.
  const auto near = net_.lanes_at({30.0, 5.0}, 2.0);
  ASSERT_EQ(near.size(), 1u);
  EXPECT_EQ(near[0].lane, lane("ba_0"));
  EXPECT_NEAR(near[0].lateral_m, -3.25, 1e-9);
  // Far outside the network's bounding box.
  EXPECT_FALSE(net_.is_drivable({-500.0, 900.0}));
}

TEST_F(NetQueryTest, JunctionAreaIsDrivable) {
  // Inside the junction square but off every lane.
  EXPECT_TRUE(net_.lanes_at({105.0, 3.0}).empty());
  EXPECT_TRUE(net_.in_junction({105.0, 3.0}));
  EXPECT_TRUE(net_.is_drivable({105.0, 3.0}));
  EXPECT_FALSE(net_.in_junction({99.0, 3.0}));
}

TEST_F(NetQueryTest, LaneEndsHandOverToTheInternalLane) {
  // Half a metre past the end of ab_0: not on ab_0 any more, but on the internal lane.
  const auto past = net_.locate({100.5, -1.75});
  ASSERT_TRUE(past.has_value());
  EXPECT_EQ(past->lane, lane(":b_0_0"));
  EXPECT_NEAR(past->s_m, 0.5, 1e-9);
  // Exactly at the seam both contain the point; the normal lane wins the tie.
  EXPECT_EQ(net_.locate({100.0, -1.75})->lane, lane("ab_0"));
}

TEST_F(NetQueryTest, BendOfAPolyline) {
  const int ce = lane("ce_0");
  // On the northbound leg, 1 m east of the centre line: right of the direction of travel.
  auto at = net_.locate({201.0, 45.0});
  ASSERT_TRUE(at.has_value());
  EXPECT_EQ(at->lane, ce);
  EXPECT_NEAR(at->s_m, 45.0, 1e-9);
  EXPECT_NEAR(at->lateral_m, -1.0, 1e-9);
  EXPECT_NEAR(at->heading_rad, M_PI / 2, 1e-9);
  // On the eastbound leg: s = 50 + 20, 1.5 m north = left.
  at = net_.locate({220.0, 51.5});
  ASSERT_TRUE(at.has_value());
  EXPECT_NEAR(at->s_m, 70.0, 1e-9);
  EXPECT_NEAR(at->lateral_m, 1.5, 1e-9);
  EXPECT_NEAR(at->heading_rad, 0.0, 1e-9);
  // Outside the bend the corner point is closest: sqrt(2) m away, to the left.
  at = net_.locate({199.0, 51.0});
  ASSERT_TRUE(at.has_value());
  EXPECT_NEAR(at->s_m, 50.0, 1e-9);
  EXPECT_NEAR(at->lateral_m, std::sqrt(2.0), 1e-9);
  // sqrt(2 * 1.5^2) = 2.12 m from the corner: beyond the 2 m half width.
  EXPECT_FALSE(net_.locate({198.5, 51.5}).has_value());
}

TEST_F(NetQueryTest, PosesAndProjection) {
  const Pose2 pose = net_.lane_pose(lane("ce_0"), 75.0);
  EXPECT_NEAR(pose.x_m, 225.0, 1e-9);
  EXPECT_NEAR(pose.y_m, 50.0, 1e-9);
  EXPECT_NEAR(pose.yaw_rad, 0.0, 1e-9);
  // Clamped to the lane's end.
  const Pose2 end = net_.lane_pose(lane("ab_0"), 150.0);
  EXPECT_NEAR(end.x_m, 100.0, 1e-9);
  // Projection works however far the point is.
  const LanePosition far = net_.project(lane("ab_0"), {50.0, 10.0});
  EXPECT_NEAR(far.s_m, 50.0, 1e-9);
  EXPECT_NEAR(far.lateral_m, 11.75, 1e-9);
}

TEST_F(NetQueryTest, BoundingBoxCoversLaneSurfaces) {
  EXPECT_NEAR(net_.min_corner().x(), -1.75, 1e-9);
  EXPECT_NEAR(net_.min_corner().y(), -3.5, 1e-9);
  EXPECT_NEAR(net_.max_corner().x(), 252.0, 1e-9);
  EXPECT_NEAR(net_.max_corner().y(), 52.0, 1e-9);
}

TEST(WrapAngleTest, WrapsIntoHalfOpenRange) {
  EXPECT_NEAR(wrap_angle(3 * M_PI / 2), -M_PI / 2, 1e-12);
  EXPECT_NEAR(wrap_angle(-3 * M_PI / 2), M_PI / 2, 1e-12);
  EXPECT_NEAR(wrap_angle(0.25), 0.25, 1e-12);
  EXPECT_NEAR(wrap_angle(M_PI), -M_PI, 1e-12);
}

}  // namespace
}  // namespace indrive::env
