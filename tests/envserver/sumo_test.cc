#include "indrive/envserver/sumo.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <fstream>

#include "sim_test_net.h"
#include "testing.h"

namespace indrive::env {
namespace {

using indrive::testing::make_t_junction_net;
using indrive::testing::TempDir;

// libsumo allows one simulation per process, so tests that need one share it.
SumoConnection& shared_libsumo() {
  static std::unique_ptr<SumoConnection> connection = make_sumo_connection(SumoConfig{});
  return *connection;
}

TEST(SumoArguments, CarryTheRlSettings) {
  const auto args = sumo_arguments(SumoConfig{}, "x.net.xml", 42);
  auto value_of = [&](const std::string& flag) {
    auto it = std::find(args.begin(), args.end(), flag);
    return it == args.end() || it + 1 == args.end() ? std::string("<missing>") : *(it + 1);
  };
  EXPECT_EQ(value_of("--net-file"), "x.net.xml");
  EXPECT_DOUBLE_EQ(std::stod(value_of("--step-length")), 0.1);
  EXPECT_EQ(value_of("--seed"), "42");
  EXPECT_EQ(value_of("--time-to-teleport"), "-1");
  EXPECT_EQ(value_of("--collision.action"), "warn");
  EXPECT_EQ(value_of("--collision.check-junctions"), "true");
  EXPECT_EQ(value_of("--xml-validation"), "never");
  // Sublanes on by default (traffic keeps a turning ego as its leader), off at 0.
  EXPECT_DOUBLE_EQ(std::stod(value_of("--lateral-resolution")), 0.8);
  SumoConfig no_sublanes;
  no_sublanes.lateral_resolution_m = 0.0;
  const auto plain = sumo_arguments(no_sublanes, "x.net.xml", 42);
  EXPECT_EQ(std::find(plain.begin(), plain.end(), "--lateral-resolution"), plain.end());
}

TEST(SumoMode, ParsesKnownNamesAndRejectsOthers) {
  EXPECT_EQ(parse_sumo_mode("libsumo"), SumoMode::kLibsumo);
  EXPECT_EQ(parse_sumo_mode("libtraci"), SumoMode::kLibtraci);
  try {
    parse_sumo_mode("carla");
    FAIL() << "expected SumoError";
  } catch (const SumoError& e) {
    EXPECT_NE(std::string(e.what()).find("carla"), std::string::npos);
    EXPECT_NE(std::string(e.what()).find("libtraci"), std::string::npos);
  }
}

// ctest runs every test case in its own process, so no other libsumo connection is open here.
TEST(Libsumo, ClaimIsGivenBackWhenNoSimulationWasStarted) {
  { auto unused = make_sumo_connection(SumoConfig{}); }
  EXPECT_NO_THROW({ auto again = make_sumo_connection(SumoConfig{}); });
}

TEST(Libsumo, LoadsNetworkAndReportsItsLanes) {
  TempDir dir;
  auto& sumo = shared_libsumo();
  sumo.load(make_t_junction_net(dir.path()), 1);
  const auto lanes = sumo.lanes();
  auto it = std::find_if(lanes.begin(), lanes.end(),
                         [](const LaneGeometry& l) { return l.id == "we_0"; });
  ASSERT_NE(it, lanes.end());
  EXPECT_FALSE(it->internal);
  EXPECT_NEAR(it->width_m, 3.5, 1e-9);
  // Eastbound lane of a two-way road lies right of the centre line: y < 0, runs +x.
  EXPECT_LT(it->shape.front().y(), 0.0);
  EXPECT_GT(it->shape.back().x(), it->shape.front().x());
  EXPECT_TRUE(std::any_of(lanes.begin(), lanes.end(), [](const auto& l) { return l.internal; }));
  EXPECT_EQ(sumo.junctions().size(), 4u);
  EXPECT_EQ(sumo.find_route("we", "cn"), (std::vector<std::string>{"we", "cn"}));
}

TEST(Libsumo, TrafficDrivesAndIsReportedAtItsFootprintCentre) {
  TempDir dir;
  auto& sumo = shared_libsumo();
  sumo.load(make_t_junction_net(dir.path()), 1);
  sumo.add_vehicle("car", {"we", "ce"}, kTrafficType, 0, 50.0, 5.0);
  std::vector<VehicleState> states;
  double first_x = 0.0;
  for (int i = 0; i < 20; ++i) {
    sumo.step();
    sumo.vehicles(states);
    ASSERT_EQ(states.size(), 1u);
    if (i == 0) first_x = states[0].pose.x_m;
  }
  EXPECT_NEAR(sumo.time_s(), 2.0, 1e-9);
  const VehicleState& car = states[0];
  EXPECT_GT(car.pose.x_m, first_x + 5.0);    // it moved east
  EXPECT_NEAR(car.pose.yaw_rad, 0.0, 1e-6);  // heading east
  EXPECT_NEAR(car.length_m, 4.8, 1e-9);
  // First reported position: front bumper at 50 m along a lane starting near x = 0 (minus the
  // junction cut), so the centre is 2.4 m behind it.
  EXPECT_NEAR(first_x, 50.0 - 2.4 + 0.5, 1.5);
}

TEST(Libsumo, EgoStaysWhereItIsPlacedAndTrafficBrakesForIt) {
  TempDir dir;
  auto& sumo = shared_libsumo();
  sumo.load(make_t_junction_net(dir.path()), 3);
  sumo.add_ego("ego", "we");
  // The ego stands still in the eastbound lane at x = 100; a car approaches from behind.
  const Pose2 ego_pose{100.0, -1.75, 0.0};
  sumo.place_ego("ego", ego_pose, 0.0);
  sumo.add_vehicle("car", {"we", "ce"}, kTrafficType, 0, 20.0, 8.0);
  std::vector<VehicleState> states;
  for (int i = 0; i < 300; ++i) {
    sumo.place_ego("ego", ego_pose, 0.0);
    sumo.step();
  }
  sumo.vehicles(states);
  ASSERT_EQ(states.size(), 2u);
  const VehicleState& car = states[0].id == "car" ? states[0] : states[1];
  const VehicleState& ego = states[0].id == "ego" ? states[0] : states[1];
  EXPECT_NEAR(ego.pose.x_m, 100.0, 1e-6);
  EXPECT_NEAR(ego.pose.y_m, -1.75, 1e-6);
  // The car stopped behind the ego instead of driving through it.
  EXPECT_LT(car.pose.x_m, 100.0 - 4.8);
  EXPECT_GT(car.pose.x_m, 80.0);
  EXPECT_NEAR(car.speed_mps, 0.0, 0.1);
  EXPECT_TRUE(sumo.collisions().empty());
}

TEST(Libsumo, EgoCanBePlacedFarFromEveryLane) {
  TempDir dir;
  auto& sumo = shared_libsumo();
  sumo.load(make_t_junction_net(dir.path()), 3);
  sumo.add_ego("ego", "we");
  std::vector<VehicleState> states;
  // 15 m and then 60 m south of the road: beyond the cheap 10 m lane search.
  for (const double y : {-15.0, -60.0}) {
    EXPECT_NO_THROW(sumo.place_ego("ego", Pose2{60.0, y, 0.0}, 3.0));
    sumo.step();
    sumo.vehicles(states);
    ASSERT_EQ(states.size(), 1u);
    EXPECT_NEAR(states[0].pose.x_m, 60.0, 1e-6);
    EXPECT_NEAR(states[0].pose.y_m, y, 1e-6);
  }
}

TEST(Libsumo, EgoPlacedOntoACarIsReportedAsACollision) {
  TempDir dir;
  auto& sumo = shared_libsumo();
  sumo.load(make_t_junction_net(dir.path()), 3);
  sumo.add_ego("ego", "we");
  sumo.place_ego("ego", Pose2{30.0, -1.75, 0.0}, 0.0);
  sumo.add_vehicle("car", {"we", "ce"}, kTrafficType, 0, 80.0, 0.0);
  std::vector<VehicleState> states;
  for (int i = 0; i < 5; ++i) {
    sumo.place_ego("ego", Pose2{30.0, -1.75, 0.0}, 0.0);
    sumo.step();
  }
  sumo.vehicles(states);
  ASSERT_EQ(states.size(), 2u);
  const VehicleState& car = states[0].id == "car" ? states[0] : states[1];
  // Jump the ego onto the car: SUMO's own check must list the pair.
  bool reported = false;
  for (int i = 0; i < 3 && !reported; ++i) {
    sumo.place_ego("ego", Pose2{car.pose.x_m + 1.0, car.pose.y_m, 0.0}, 5.0);
    sumo.step();
    for (const SumoCollision& c : sumo.collisions()) {
      reported = reported || c.collider == "ego" || c.victim == "ego";
    }
  }
  EXPECT_TRUE(reported);
}

TEST(Libsumo, SecondSimulationInOneProcessIsRefused) {
  shared_libsumo();
  EXPECT_THROW(make_sumo_connection(SumoConfig{}), SumoError);
}

TEST(Libsumo, MissingAndMalformedNetworksAreNamed) {
  TempDir dir;
  auto& sumo = shared_libsumo();
  try {
    sumo.load(dir.path() / "nope.net.xml", 1);
    FAIL() << "expected SumoError";
  } catch (const SumoError& e) {
    EXPECT_NE(std::string(e.what()).find("nope.net.xml"), std::string::npos);
  }
  const auto bad = dir.path() / "bad.net.xml";
  std::ofstream(bad) << "<net><edge id=\"x\"><lane id=";
  try {
    sumo.load(bad, 1);
    FAIL() << "expected SumoError";
  } catch (const SumoError& e) {
    EXPECT_NE(std::string(e.what()).find("bad.net.xml"), std::string::npos);
  }
}

TEST(Libtraci, MissingSumoBinaryIsNamed) {
  SumoConfig config;
  config.mode = SumoMode::kLibtraci;
  config.sumo_binary = "/nonexistent/bin/sumo";
  try {
    make_sumo_connection(config);
    FAIL() << "expected SumoError";
  } catch (const SumoError& e) {
    EXPECT_NE(std::string(e.what()).find("/nonexistent/bin/sumo"), std::string::npos);
  }
}

TEST(Libtraci, SameTrajectoryAsLibsumo) {
  TempDir dir;
  const auto net = make_t_junction_net(dir.path());
  SumoConfig config;
  config.mode = SumoMode::kLibtraci;
  auto remote = make_sumo_connection(config);
  auto& local = shared_libsumo();
  std::vector<VehicleState> a, b;
  for (SumoConnection* sumo : {remote.get(), &local}) {
    sumo->load(net, 5);
    sumo->add_vehicle("car", {"we", "cn"}, kTrafficType, 0, 10.0, 0.0);
    for (int i = 0; i < 300; ++i) sumo->step();
  }
  remote->vehicles(a);
  local.vehicles(b);
  ASSERT_EQ(a.size(), 1u);
  ASSERT_EQ(b.size(), 1u);
  EXPECT_NEAR(a[0].pose.x_m, b[0].pose.x_m, 1e-6);
  EXPECT_NEAR(a[0].pose.y_m, b[0].pose.y_m, 1e-6);
  EXPECT_GT(a[0].pose.y_m, 5.0);  // it turned north at the junction
}

}  // namespace
}  // namespace indrive::env
