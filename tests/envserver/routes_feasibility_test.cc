// Every built-in route can be driven with the ego's steering set {-0.3, 0, +0.3} at 3 and 5 m/s
// without leaving the lane: a geometric check, independent of SUMO, that the routes and the
// junction radii suit the action set. The car is a kinematic bicycle (wheelbase 2.9 m, wheel
// angle = steer * 70 deg, applied at once); a short look-ahead picks each 0.1 s steer.
#include <gtest/gtest.h>

#include <cmath>

#include "net_test_town.h"

namespace indrive::env {
namespace {

constexpr double kWheelbaseM = 2.9;
constexpr double kMaxWheelAngleRad = 70.0 * M_PI / 180.0;
constexpr double kStepS = 0.1;
constexpr double kSteers[] = {-0.3, 0.0, 0.3};
// A 2.1 m wide car in a 3.5 m lane has 0.7 m to spare on each side.
constexpr double kMaxLateralM = 0.7;

struct Car {
  double x, y, yaw;
};

// Advances the rear-axle pose by one control step in ten sub-steps.
Car advance(Car car, double steer, double speed_mps) {
  const double curvature = std::tan(steer * kMaxWheelAngleRad) / kWheelbaseM;
  const double dt = kStepS / 10.0;
  for (int i = 0; i < 10; ++i) {
    car.x += speed_mps * std::cos(car.yaw) * dt;
    car.y += speed_mps * std::sin(car.yaw) * dt;
    car.yaw += speed_mps * curvature * dt;
  }
  return car;
}

struct FeasibilityCase {
  std::string town;
  std::string route;
  double speed_mps;
};

void PrintTo(const FeasibilityCase& c, std::ostream* os) {
  *os << c.town << "/" << c.route << "@" << c.speed_mps;
}

class RouteFeasibilityTest : public ::testing::TestWithParam<FeasibilityCase> {};

TEST_P(RouteFeasibilityTest, DrivableWithTheDiscreteSteeringSet) {
  const FeasibilityCase& param = GetParam();
  const Route& route = find_route(testing::cached_town(param.town).routes, param.route);
  // The car's centre sits 1.45 m ahead of the rear axle; track the centre.
  auto centre = [](const Car& car) {
    return Eigen::Vector2d(car.x + 0.5 * kWheelbaseM * std::cos(car.yaw),
                           car.y + 0.5 * kWheelbaseM * std::sin(car.yaw));
  };
  const Pose2 start = route.start_pose();
  Car car{start.x_m - 0.5 * kWheelbaseM * std::cos(start.yaw_rad),
          start.y_m - 0.5 * kWheelbaseM * std::sin(start.yaw_rad), start.yaw_rad};
  double s = 0.0;
  double worst = 0.0;
  const int max_steps = static_cast<int>(route.length_m() / (param.speed_mps * kStepS)) + 50;
  int step = 0;
  for (; step < max_steps; ++step) {
    // Look ahead 0.6 s holding each steer, then straight: the smallest squared offset from the
    // route over that horizon wins.
    double best_cost = INFINITY;
    double best_steer = 0.0;
    for (double first : kSteers) {
      for (double second : kSteers) {
        Car probe = car;
        double cost = 0.0;
        double probe_s = s;
        for (int k = 0; k < 6; ++k) {
          probe = advance(probe, k < 3 ? first : second, param.speed_mps);
          const RoutePoint at = route.project(centre(probe), probe_s, 10.0);
          probe_s = at.s_m;
          cost += at.lateral_m * at.lateral_m;
        }
        if (cost < best_cost) {
          best_cost = cost;
          best_steer = first;
        }
      }
    }
    car = advance(car, best_steer, param.speed_mps);
    const RoutePoint at = route.project(centre(car), s, 10.0);
    const double delta = route.is_loop() ? wrap_angle((at.s_m - s) / route.length_m() * 2 * M_PI) *
                                               route.length_m() / (2 * M_PI)
                                         : at.s_m - s;
    ASSERT_GT(delta, 0.0) << "no progress at s = " << s;
    s = at.s_m;
    worst = std::max(worst, std::abs(at.lateral_m));
    ASSERT_LT(std::abs(at.lateral_m), kMaxLateralM) << "left the lane at s = " << s;
    if (!route.is_loop() && s >= route.length_m() - 1.0) break;
  }
  RecordProperty("worst_lateral_m", std::to_string(worst));
  EXPECT_GT(step, 0);
}

std::vector<FeasibilityCase> feasibility_cases() {
  std::vector<FeasibilityCase> cases;
  for (const std::string town : {"town01", "town02"}) {
    for (const auto name : kRouteNames) {
      for (double speed : {3.0, 5.0}) cases.push_back({town, std::string(name), speed});
    }
  }
  return cases;
}

INSTANTIATE_TEST_SUITE_P(Towns, RouteFeasibilityTest, ::testing::ValuesIn(feasibility_cases()),
                         [](const ::testing::TestParamInfo<FeasibilityCase>& info) {
                           return info.param.town + "_" + info.param.route + "_" +
                                  std::to_string(static_cast<int>(info.param.speed_mps)) + "mps";
                         });

}  // namespace
}  // namespace indrive::env
