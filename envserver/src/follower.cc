#include "indrive/envserver/follower.h"

#include <algorithm>
#include <cmath>
#include <numbers>

namespace indrive::env {

WaypointFollower::WaypointFollower(const Route& route, const EgoParams& ego,
                                   const FollowerConfig& config)
    : route_(&route), ego_(ego), config_(config) {}

void WaypointFollower::reset() {
  s_m_ = 0.0;
  curvature_error_ = 0.0;
}

double WaypointFollower::curvature_of_steer(double steer) const {
  const double wheel = -steer * ego_.max_wheel_angle_deg * std::numbers::pi / 180.0;
  const double beta = std::atan(ego_.rear_axle_to_centre_m / ego_.wheelbase_m * std::tan(wheel));
  return std::sin(beta) / ego_.rear_axle_to_centre_m;
}

int WaypointFollower::act(const EgoState& ego) {
  const Eigen::Vector2d position(ego.pose.x_m, ego.pose.y_m);
  s_m_ = route_->project(position, s_m_, config_.search_window_m).s_m;

  // Pure pursuit: the arc through the look-ahead point tangent to the heading has curvature
  // 2 * lateral / distance^2, lateral measured in the ego frame.
  const double lookahead = std::clamp(config_.lookahead_s * ego.speed_mps, config_.min_lookahead_m,
                                      config_.max_lookahead_m);
  const Pose2 target = route_->pose_at(s_m_ + lookahead);
  const double dx = target.x_m - ego.pose.x_m;
  const double dy = target.y_m - ego.pose.y_m;
  const double lateral = -std::sin(ego.pose.yaw_rad) * dx + std::cos(ego.pose.yaw_rad) * dy;
  const double dist2 = std::max(dx * dx + dy * dy, 1e-6);
  const double wanted = 2.0 * lateral / dist2;

  // Sigma-delta: choose the available curvature nearest to the wanted one plus the error left
  // over from earlier steps, so the average curvature follows the wanted one.
  const double goal = wanted + curvature_error_;
  int steer_index = 1;
  double best = INFINITY;
  for (int i = 0; i < 3; ++i) {
    const double error = std::abs(goal - curvature_of_steer(kSteerLevels[i]));
    if (error < best) best = error, steer_index = i;
  }
  const double applied = curvature_of_steer(kSteerLevels[steer_index]);
  // Bounded so a long saturated turn does not wind up and overshoot after it.
  const double k_max = curvature_of_steer(-kSteerLevels[2]);
  curvature_error_ = std::clamp(goal - applied, -k_max, k_max);

  // Throttle: the levels bracketing the target's settle speed.
  const double target_speed = config_.target_speed_mps;
  EgoModel model(ego_);
  int low = 0;
  int high = 2;
  for (int i = 0; i < 3; ++i) {
    if (model.settle_speed_mps(kThrottleLevels[i]) <= target_speed) low = i;
  }
  for (int i = 2; i >= 0; --i) {
    if (model.settle_speed_mps(kThrottleLevels[i]) >= target_speed) high = i;
  }
  const int throttle_index = ego.speed_mps < target_speed ? high : low;
  return encode_action(steer_index, throttle_index);
}

}  // namespace indrive::env
