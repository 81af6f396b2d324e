// A scripted driver that follows a route with the 9 discrete actions only: pure pursuit for
// steering, throttle choice for speed. It exists to prove the tasks are feasible with this
// action set (every route, 3 and 5 m/s, no failure event) and to record demonstration videos.
//
// Steering: pure pursuit gives the curvature that reaches a look-ahead point on the route;
// only three curvatures are available (left, straight, right), so a sigma-delta modulator picks
// among them such that their running mean follows the wanted curvature.
// Speed: full throttle step (0.3) below the target, the next lower level above it.
//
//   WaypointFollower follower(route, EgoParams{}, {.target_speed_mps = 5.0});
//   follower.reset();
//   int action = follower.act(env.ego());
#pragma once

#include "indrive/envserver/ego.h"
#include "indrive/envserver/routes.h"

namespace indrive::env {

// Tuning of the follower.
struct FollowerConfig {
  double target_speed_mps = 5.0;
  double min_lookahead_m = 4.0;
  double lookahead_s = 1.0;  // look-ahead distance grows with speed: this many seconds
  double max_lookahead_m = 8.0;
  double search_window_m = 20.0;  // route projection searches this far around the last point
};

class WaypointFollower {
 public:
  // route must outlive the follower.
  WaypointFollower(const Route& route, const EgoParams& ego, const FollowerConfig& config = {});
  // Restarts at the route start.
  void reset();
  // Returns the action index for the ego's current state.
  int act(const EgoState& ego);

  // Curvature (1/m, positive left) the car drives with a steer command.
  double curvature_of_steer(double steer) const;

 private:
  const Route* route_;
  EgoParams ego_;
  FollowerConfig config_;
  double s_m_ = 0.0;
  double curvature_error_ = 0.0;  // sigma-delta accumulator
};

}  // namespace indrive::env
