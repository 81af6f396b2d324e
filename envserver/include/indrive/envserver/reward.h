// Task rewards for lane following and collision avoidance (fine-tuning and the Dreamer
// baseline only; pretraining computes no reward at all). Pure functions of one step's state.
//
// r = r_waypoint + r_speed + r_lane + r_collision + r_destination + r_time, with
//   r_waypoint    = w_waypoint * n_passed            (route waypoints, ~2 m apart, newly passed)
//   r_speed       = speed_scale * (v* - |v_long - v*| - 2 * min(|v_lat|, 0.5 m/s))
//                   v_long, v_lat: ego velocity along and across the next waypoint's heading;
//                   best (speed_scale * v*) when driving at v* straight along the route.
//   r_lane        = -w_lane * min(1, ((d - 0.2 w) / (0.5 w - 0.2 w))^2) for d > 0.2 w, else 0
//                   d: |lateral offset| from the route centre line, w: lane width; the first
//                   20% of the width is free, the penalty reaches w_lane at half a lane width.
//   r_collision   = -w_collision * max(speed / v*, 0.2)   on a collision step, else 0
//                   (proportional to speed, w_collision at v*; the floor keeps a collision
//                   at a standstill from being free)
//   r_destination = +w_destination on the step the destination is reached / the loop closes
//   r_time        = -w_time every step.
//
//   RewardWeights weights = reward_weights("lane_following");
//   RewardTerms terms = compute_reward(weights, inputs);
//   double r = terms.total();
#pragma once

#include <Eigen/Core>
#include <string_view>

namespace indrive::env {

// Weights of one task (the paper's table).
struct RewardWeights {
  double waypoint = 1.0;
  double target_speed_mps = 5.0;  // v*
  double speed_scale = 0.05;
  double lane = 2.0;
  double collision = 30.0;
  double destination = 100.0;
  double time = 0.01;
};

// lane_following: waypoint 1.0, v* 5.0, speed scale 0.05, lane 2.0, collision 30,
// destination 100, time 0.01.
RewardWeights lane_following_weights();
// collision_avoidance: waypoint 0.5, v* 3.0, speed scale 0.03, lane 1.0, collision 80,
// destination 100, time 0.01.
RewardWeights collision_avoidance_weights();
// Returns the weights of a task by name; throws std::invalid_argument listing the known ones.
RewardWeights reward_weights(std::string_view task);

// What the reward of one step depends on.
struct RewardInputs {
  int waypoints_passed = 0;                // new route waypoints passed this step
  Eigen::Vector2d velocity_mps{0.0, 0.0};  // ego velocity in the world frame
  double next_waypoint_heading_rad = 0.0;  // heading of the next route waypoint
  double lateral_offset_m = 0.0;           // from the route centre line
  double lane_width_m = 3.5;
  bool collision = false;
  bool destination_reached = false;
};

// The terms of one step's reward, kept apart for logging.
struct RewardTerms {
  double waypoint = 0.0;
  double speed = 0.0;
  double lane = 0.0;
  double collision = 0.0;
  double destination = 0.0;
  double time = 0.0;
  // Returns the sum of all terms.
  double total() const { return waypoint + speed + lane + collision + destination + time; }
};

// Computes every term of the formula in this header's overview.
RewardTerms compute_reward(const RewardWeights& weights, const RewardInputs& inputs);

// The speed-tracking term alone (see the overview).
double speed_reward(const RewardWeights& weights, const Eigen::Vector2d& velocity_mps,
                    double heading_rad);
// The lane-keeping term alone (see the overview); non-positive.
double lane_reward(const RewardWeights& weights, double lateral_offset_m, double lane_width_m);
// The collision term alone for a collision at `speed_mps` (see the overview); non-positive.
double collision_reward(const RewardWeights& weights, double speed_mps);

}  // namespace indrive::env
