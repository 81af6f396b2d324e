// Small geometry helpers shared by the camera, the scene cache and the bird's-eye view.
#pragma once

#include <Eigen/Core>
#include <array>
#include <cmath>

#include "indrive/envserver/scene.h"

namespace indrive::env::detail {

// The four footprint corners of a box, counter-clockwise seen from above (z up).
inline std::array<Eigen::Vector2d, 4> footprint(const Box& box) {
  const Eigen::Vector2d centre(box.pose.x_m, box.pose.y_m);
  const Eigen::Vector2d along(std::cos(box.pose.yaw_rad), std::sin(box.pose.yaw_rad));
  const Eigen::Vector2d across(-along.y(), along.x());
  const Eigen::Vector2d a = 0.5 * box.length_m * along;
  const Eigen::Vector2d b = 0.5 * box.width_m * across;
  return {centre - a - b, centre + a - b, centre + a + b, centre - a + b};
}

}  // namespace indrive::env::detail
