#include "indrive/envserver/reward.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace indrive::env {

namespace {
// Lateral speed counts up to this value only, so one bad step cannot dominate the return.
constexpr double kLateralSpeedCapMps = 0.5;
// The lateral speed penalty weighs twice the longitudinal tracking error.
constexpr double kLateralSpeedWeight = 2.0;
// Share of the lane width around the centre line where drifting costs nothing.
constexpr double kLaneFreeBand = 0.2;
// A collision at a standstill still costs this share of the full penalty.
constexpr double kCollisionFloor = 0.2;
}  // namespace

RewardWeights lane_following_weights() {
  return RewardWeights{.waypoint = 1.0,
                       .target_speed_mps = 5.0,
                       .speed_scale = 0.05,
                       .lane = 2.0,
                       .collision = 30.0,
                       .destination = 100.0,
                       .time = 0.01};
}

RewardWeights collision_avoidance_weights() {
  return RewardWeights{.waypoint = 0.5,
                       .target_speed_mps = 3.0,
                       .speed_scale = 0.03,
                       .lane = 1.0,
                       .collision = 80.0,
                       .destination = 100.0,
                       .time = 0.01};
}

RewardWeights reward_weights(std::string_view task) {
  if (task == "lane_following") return lane_following_weights();
  if (task == "collision_avoidance") return collision_avoidance_weights();
  throw std::invalid_argument("unknown task '" + std::string(task) +
                              "': known tasks are lane_following, collision_avoidance");
}

double speed_reward(const RewardWeights& weights, const Eigen::Vector2d& velocity_mps,
                    double heading_rad) {
  const Eigen::Vector2d along(std::cos(heading_rad), std::sin(heading_rad));
  const double v_long = velocity_mps.dot(along);
  const double v_lat = along.x() * velocity_mps.y() - along.y() * velocity_mps.x();
  const double target = weights.target_speed_mps;
  return weights.speed_scale *
         (target - std::abs(v_long - target) -
          kLateralSpeedWeight * std::min(std::abs(v_lat), kLateralSpeedCapMps));
}

double lane_reward(const RewardWeights& weights, double lateral_offset_m, double lane_width_m) {
  const double distance = std::abs(lateral_offset_m);
  const double free_band = kLaneFreeBand * lane_width_m;
  const double half = 0.5 * lane_width_m;
  if (distance <= free_band || half <= free_band) return 0.0;
  const double ratio = std::min(1.0, (distance - free_band) / (half - free_band));
  return -weights.lane * ratio * ratio;
}

double collision_reward(const RewardWeights& weights, double speed_mps) {
  const double relative = std::abs(speed_mps) / weights.target_speed_mps;
  return -weights.collision * std::max(relative, kCollisionFloor);
}

RewardTerms compute_reward(const RewardWeights& weights, const RewardInputs& inputs) {
  RewardTerms terms;
  terms.waypoint = weights.waypoint * std::max(0, inputs.waypoints_passed);
  terms.speed = speed_reward(weights, inputs.velocity_mps, inputs.next_waypoint_heading_rad);
  terms.lane = lane_reward(weights, inputs.lateral_offset_m, inputs.lane_width_m);
  terms.collision = inputs.collision ? collision_reward(weights, inputs.velocity_mps.norm()) : 0.0;
  terms.destination = inputs.destination_reached ? weights.destination : 0.0;
  terms.time = -weights.time;
  return terms;
}

}  // namespace indrive::env
