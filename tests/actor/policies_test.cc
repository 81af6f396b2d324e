// Tests of policies.h: policy source and head names, and the oracle's traffic geometry.
#include "indrive/actor/policies.h"

#include <gtest/gtest.h>

#include <cstring>
#include <fstream>
#include <numbers>

#include "eval_test_support.h"
#include "indrive/actor/eval_protocol_record.h"
#include "indrive/actor/snapshot_file.h"
#include "indrive/agent/agent.h"
#include "indrive/agent/policy.h"
#include "indrive/basics/checksum.h"
#include "indrive/envserver/town.h"
#include "indrive/nn/serialize.h"
#include "testing.h"

namespace indrive::actor {
namespace {

using test_support::eval_error_of;
using test_support::tiny_snapshot;

TEST(Policies, PolicySourceAndHeadNamesAreCheckedWithTheAllowedValues) {
  EXPECT_EQ(parse_policy_source("oracle"), PolicySource::kOracle);
  EXPECT_EQ(parse_policy_source("random"), PolicySource::kRandom);
  EXPECT_EQ(parse_policy_source("snapshot"), PolicySource::kSnapshot);
  const std::string message = eval_error_of([] { parse_policy_source("scripted"); });
  EXPECT_NE(message.find("'scripted'"), std::string::npos) << message;
  EXPECT_NE(message.find("oracle"), std::string::npos) << message;

  EXPECT_EQ(resolve_head("auto", "zero_shot"), PolicyHead::kExploration);
  EXPECT_EQ(resolve_head("auto", "few_shot"), PolicyHead::kTask);
  EXPECT_EQ(resolve_head("task", "zero_shot"), PolicyHead::kTask);
  EXPECT_NE(eval_error_of([] { resolve_head("critic", "zero_shot"); }).find("'critic'"),
            std::string::npos);
}

TEST(Policies, LeaderAheadSeesOnlyVehiclesOnTheRouteInFront) {
  const env::Town town = env::load_town("town01");
  const env::Route& route = env::find_route(town.routes, "right_loop");
  auto box_at = [&](double s_m, double lateral_m) {
    const env::Pose2 pose = route.pose_at(s_m);
    env::Box box;
    box.pose = {pose.x_m - lateral_m * std::sin(pose.yaw_rad),
                pose.y_m + lateral_m * std::cos(pose.yaw_rad), pose.yaw_rad};
    return box;
  };
  const double ego_s = 50.0;
  const std::vector<env::Box> ahead = {box_at(ego_s + 12.0, 0.3)};
  EXPECT_TRUE(leader_ahead(route, ego_s, ahead, 20.0, 2.2));
  const std::vector<env::Box> far = {box_at(ego_s + 35.0, 0.0)};
  EXPECT_FALSE(leader_ahead(route, ego_s, far, 20.0, 2.2));
  const std::vector<env::Box> behind = {box_at(ego_s - 8.0, 0.0)};
  EXPECT_FALSE(leader_ahead(route, ego_s, behind, 20.0, 2.2));
  // Oncoming traffic in the next lane (3.5 m to the left) is not a leader.
  const std::vector<env::Box> oncoming = {box_at(ego_s + 10.0, 3.5)};
  EXPECT_FALSE(leader_ahead(route, ego_s, oncoming, 20.0, 2.2));
  // On a loop, "ahead" wraps past the start.
  const std::vector<env::Box> wrapped = {box_at(5.0, 0.0)};
  EXPECT_TRUE(leader_ahead(route, route.length_m() - 6.0, wrapped, 20.0, 2.2));
}

// A car ahead to the left, oncoming and starting a left turn into the ego's lane: a straight
// line keeps it 6 m to the side, its turn rate brings it across the ego's path.
TEST(Policies, ConflictAheadFollowsATurningCarAlongItsTurn) {
  const env::Town town = env::load_town("town01");
  const env::Route& route = env::find_route(town.routes, "right_loop");
  const double ego_s = 50.0;
  const env::Pose2 ego_pose = route.pose_at(ego_s);
  // The test needs a straight stretch ahead of the ego.
  ASSERT_NEAR(env::wrap_angle(route.pose_at(ego_s + 20.0).yaw_rad - ego_pose.yaw_rad), 0.0, 0.05);
  const env::Box ego{env::SemanticClass::kVehicle, ego_pose, 4.8, 2.1, 1.5};
  const double c = std::cos(ego_pose.yaw_rad), s = std::sin(ego_pose.yaw_rad);
  auto world = [&](double forward, double left) {
    return Eigen::Vector2d(ego_pose.x_m + forward * c - left * s,
                           ego_pose.y_m + forward * s + left * c);
  };
  const Eigen::Vector2d at = world(20.0, 6.0);
  const double heading = ego_pose.yaw_rad + std::numbers::pi;  // oncoming
  const std::vector<env::Box> others = {
      {env::SemanticClass::kVehicle, {at.x(), at.y(), heading}, 4.8, 2.1, 1.5}};
  const std::vector<Eigen::Vector2d> velocity = {
      5.0 * Eigen::Vector2d(std::cos(heading), std::sin(heading))};
  const OracleOptions options;
  EXPECT_FALSE(conflict_ahead(route, ego, ego_s, 5.0, others, velocity, options));
  const std::vector<double> straight = {0.0};
  EXPECT_FALSE(conflict_ahead(route, ego, ego_s, 5.0, others, velocity, options, straight));
  const std::vector<double> turning_left = {0.5};  // rad/s, a 10 m radius at 5 m/s
  EXPECT_TRUE(conflict_ahead(route, ego, ego_s, 5.0, others, velocity, options, turning_left));
  // Turning right it leaves the ego's road.
  const std::vector<double> turning_right = {-0.5};
  EXPECT_FALSE(conflict_ahead(route, ego, ego_s, 5.0, others, velocity, options, turning_right));
}

TEST(Policies, FollowerBehindIsACarCloseBehindInLine) {
  const env::Box ego{
      env::SemanticClass::kVehicle, {10.0, 5.0, std::numbers::pi / 2}, 4.8, 2.1, 1.5};
  auto box_at = [](double x, double y) {
    return std::vector<env::Box>{{env::SemanticClass::kVehicle, {x, y, 0.0}, 4.8, 2.1, 1.5}};
  };
  // The ego faces +y: behind is -y.
  EXPECT_TRUE(follower_behind(ego, box_at(10.5, -3.0), 15.0));
  EXPECT_FALSE(follower_behind(ego, box_at(10.0, -12.0), 15.0));  // 17 m back
  EXPECT_FALSE(follower_behind(ego, box_at(14.0, -3.0), 15.0));   // the next lane over
  EXPECT_FALSE(follower_behind(ego, box_at(10.0, 12.0), 15.0));   // ahead
}

}  // namespace
}  // namespace indrive::actor
