#include "indrive/envserver/ego.h"

#include <algorithm>
#include <cmath>
#include <numbers>

#include "indrive/basics/check.h"

namespace indrive::env {

Control decode_action(int action) {
  INDRIVE_CHECK(action >= 0 && action < kNumActions) << "action " << action << " not in [0, 9)";
  return Control{kSteerLevels[action / 3], kThrottleLevels[action % 3]};
}

int encode_action(int steer_index, int throttle_index) {
  INDRIVE_CHECK(steer_index >= 0 && steer_index < 3 && throttle_index >= 0 && throttle_index < 3)
      << "steer index " << steer_index << ", throttle index " << throttle_index;
  return steer_index * 3 + throttle_index;
}

EgoState EgoModel::step(const EgoState& state, const Control& control) const {
  const EgoParams& p = params_;
  const double steer = std::clamp(control.steer, -1.0, 1.0);
  const double throttle = std::clamp(control.throttle, 0.0, 1.0);

  // Positive steer turns right, i.e. clockwise, i.e. negative yaw rate.
  const double wheel_rad = -steer * p.max_wheel_angle_deg * std::numbers::pi / 180.0;
  const double beta = std::atan(p.rear_axle_to_centre_m / p.wheelbase_m * std::tan(wheel_rad));

  // Semi-implicit Euler: the new speed moves the car, which keeps a stop exact at v = 0.
  const double accel = p.drive_accel_mps2 * throttle - p.drag_per_s * state.speed_mps -
                       (state.speed_mps > 0.0 || throttle > 0.0 ? p.rolling_mps2 : 0.0);
  const double speed = std::max(0.0, state.speed_mps + accel * p.dt_s);

  EgoState next;
  next.speed_mps = speed;
  next.yaw_rate_radps = speed / p.rear_axle_to_centre_m * std::sin(beta);
  // Midpoint heading for the translation: exact for constant-curvature arcs to second order.
  const double mid_yaw = state.pose.yaw_rad + 0.5 * next.yaw_rate_radps * p.dt_s;
  next.pose.x_m = state.pose.x_m + speed * std::cos(mid_yaw + beta) * p.dt_s;
  next.pose.y_m = state.pose.y_m + speed * std::sin(mid_yaw + beta) * p.dt_s;
  next.pose.yaw_rad =
      std::remainder(state.pose.yaw_rad + next.yaw_rate_radps * p.dt_s, 2.0 * std::numbers::pi);
  return next;
}

double EgoModel::settle_speed_mps(double throttle) const {
  return std::max(
      0.0, (params_.drive_accel_mps2 * throttle - params_.rolling_mps2) / params_.drag_per_s);
}

Box EgoModel::box(const Pose2& pose) const {
  return Box{SemanticClass::kVehicle, pose, params_.length_m, params_.width_m, params_.height_m};
}

}  // namespace indrive::env
