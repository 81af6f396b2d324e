// The ego car: a kinematic bicycle model driven by the 9 discrete actions.
//
// Actions: a = steer_index * 3 + throttle_index, with
//   steer    {-0.3, 0.0, +0.3}[steer_index]      (positive steers right, as in CARLA)
//   throttle { 0.0, 0.2,  0.3}[throttle_index]   (brake is always 0)
// so a = 4 is straight at throttle 0.2, a = 2 is hard left at throttle 0.3.
//
// Longitudinal model (per unit mass): dv/dt = k * throttle - b * v - r, v >= 0, where k is the
// drive acceleration at full throttle, b lumps drivetrain drag and engine braking, and r is
// rolling resistance. The defaults settle throttle 0.2 at 3.5 m/s and 0.3 at 6 m/s, so the
// task target speeds 3 and 5 m/s are reachable by alternating throttle levels, and throttle 0
// coasts down to a stop.
//
// Lateral model: wheel angle = steer * max_wheel_angle (70 deg), slip angle at the footprint
// centre beta = atan(l_r / L * tan(wheel)); steer 0.3 gives a turn radius of about 7.7 m.
//
//   EgoModel model;
//   EgoState ego{.pose = spawn};
//   ego = model.step(ego, decode_action(4));
#pragma once

#include <array>

#include "indrive/envserver/scene.h"

namespace indrive::env {

inline constexpr int kNumActions = 9;
inline constexpr std::array<double, 3> kSteerLevels = {-0.3, 0.0, 0.3};
inline constexpr std::array<double, 3> kThrottleLevels = {0.0, 0.2, 0.3};

// One control command.
struct Control {
  double steer = 0.0;     // [-1, 1], positive steers right
  double throttle = 0.0;  // [0, 1]
};

// Returns the control of action index a in [0, 9); INDRIVE_CHECKs the range.
Control decode_action(int action);
// Returns the action index of a steer index and a throttle index, each in [0, 3).
int encode_action(int steer_index, int throttle_index);

// Physical parameters of the ego car (CARLA-like).
struct EgoParams {
  double length_m = 4.8;
  double width_m = 2.1;
  double height_m = 1.5;
  double wheelbase_m = 2.9;
  double rear_axle_to_centre_m = 1.45;  // l_r: the footprint centre sits mid-wheelbase
  double max_wheel_angle_deg = 70.0;    // wheel angle at steer 1.0
  double drive_accel_mps2 = 7.5;        // k: acceleration per unit throttle
  double drag_per_s = 0.3;              // b
  double rolling_mps2 = 0.45;           // r
  double dt_s = 0.1;
};

// Kinematic state of the ego.
struct EgoState {
  Pose2 pose;  // footprint centre and heading
  double speed_mps = 0.0;
  double yaw_rate_radps = 0.0;  // of the last step
};

// Integrates the bicycle model.
class EgoModel {
 public:
  explicit EgoModel(const EgoParams& params = {}) : params_(params) {}

  // Returns the state one dt later under a control.
  EgoState step(const EgoState& state, const Control& control) const;
  // Speed at which a constant throttle settles (the longitudinal fixed point).
  double settle_speed_mps(double throttle) const;
  // The ego's footprint as a box at the given pose.
  Box box(const Pose2& pose) const;

  const EgoParams& params() const { return params_; }

 private:
  EgoParams params_;
};

}  // namespace indrive::env
