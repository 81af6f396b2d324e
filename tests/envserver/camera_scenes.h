// Hand-built scenes for the camera tests and the render benchmark.
#pragma once

#include <random>
#include <vector>

#include "indrive/envserver/scene.h"

namespace indrive::env::testing {

// A straight two-lane road along +x: road |y| < 3.5 m for x in [-100, 300], a solid centre
// line at y = 0 (0.15 m), sidewalks 3.5 < |y| < 5.5, vegetation elsewhere. The right lane
// centre is y = -1.75.
inline StaticScene straight_road() {
  StaticScene scene;
  scene.ground_class = SemanticClass::kVegetation;
  scene.ground.push_back(
      {SemanticClass::kSidewalk, {{-100, -5.5}, {300, -5.5}, {300, 5.5}, {-100, 5.5}}});
  scene.ground.push_back(
      {SemanticClass::kRoad, {{-100, -3.5}, {300, -3.5}, {300, 3.5}, {-100, 3.5}}});
  scene.lines.push_back({{{-100, 0.0}, {300, 0.0}}, 0.15, false});
  scene.min_corner = {-100, -50};
  scene.max_corner = {300, 50};
  return scene;
}

// A synthetic town: a grid of blocks_x x blocks_y blocks of block_m metres between road
// centre lines, two-lane roads (7 m) with a dashed centre line and solid edge lines, 2 m
// sidewalks, and buildings (or vegetation blocks) around every block's edge.
inline StaticScene grid_town(int blocks_x = 5, int blocks_y = 4, double block_m = 80.0,
                             unsigned seed = 7) {
  StaticScene scene;
  scene.ground_class = SemanticClass::kVegetation;
  const double half_road = 3.5, sidewalk = 2.0;
  const double size_x = blocks_x * block_m, size_y = blocks_y * block_m;
  // Sidewalk strips first, roads over them, so crossings stay road.
  for (int i = 0; i <= blocks_x; ++i) {
    const double x = i * block_m, w = half_road + sidewalk;
    scene.ground.push_back({SemanticClass::kSidewalk,
                            {{x - w, -w}, {x + w, -w}, {x + w, size_y + w}, {x - w, size_y + w}}});
  }
  for (int j = 0; j <= blocks_y; ++j) {
    const double y = j * block_m, w = half_road + sidewalk;
    scene.ground.push_back({SemanticClass::kSidewalk,
                            {{-w, y - w}, {size_x + w, y - w}, {size_x + w, y + w}, {-w, y + w}}});
  }
  for (int i = 0; i <= blocks_x; ++i) {
    const double x = i * block_m, w = half_road;
    scene.ground.push_back({SemanticClass::kRoad,
                            {{x - w, -w}, {x + w, -w}, {x + w, size_y + w}, {x - w, size_y + w}}});
  }
  for (int j = 0; j <= blocks_y; ++j) {
    const double y = j * block_m, w = half_road;
    scene.ground.push_back({SemanticClass::kRoad,
                            {{-w, y - w}, {size_x + w, y - w}, {size_x + w, y + w}, {-w, y + w}}});
  }
  // Lines per block side: dashed centre lines and solid edges, stopping short of junctions.
  for (int i = 0; i <= blocks_x; ++i)
    for (int j = 0; j < blocks_y; ++j) {
      const double x = i * block_m, y0 = j * block_m + half_road,
                   y1 = (j + 1) * block_m - half_road;
      scene.lines.push_back({{{x, y0}, {x, y1}}, 0.15, true});
      scene.lines.push_back({{{x - half_road + 0.2, y0}, {x - half_road + 0.2, y1}}, 0.15, false});
      scene.lines.push_back({{{x + half_road - 0.2, y0}, {x + half_road - 0.2, y1}}, 0.15, false});
    }
  for (int j = 0; j <= blocks_y; ++j)
    for (int i = 0; i < blocks_x; ++i) {
      const double y = j * block_m, x0 = i * block_m + half_road,
                   x1 = (i + 1) * block_m - half_road;
      scene.lines.push_back({{{x0, y}, {x1, y}}, 0.15, true});
      scene.lines.push_back({{{x0, y - half_road + 0.2}, {x1, y - half_road + 0.2}}, 0.15, false});
      scene.lines.push_back({{{x0, y + half_road - 0.2}, {x1, y + half_road - 0.2}}, 0.15, false});
    }
  // Buildings along each block's four sides, set back 3 m from the sidewalk.
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> height(6.0, 25.0), depth(8.0, 14.0);
  std::bernoulli_distribution green(0.2);
  const double inset = half_road + sidewalk + 3.0;
  for (int i = 0; i < blocks_x; ++i)
    for (int j = 0; j < blocks_y; ++j) {
      const double x0 = i * block_m + inset, x1 = (i + 1) * block_m - inset;
      const double y0 = j * block_m + inset, y1 = (j + 1) * block_m - inset;
      const int per_side = 3;
      const double len_x = (x1 - x0) / per_side, len_y = (y1 - y0) / per_side;
      for (int k = 0; k < per_side; ++k) {
        const SemanticClass cls =
            green(rng) ? SemanticClass::kVegetation : SemanticClass::kBuilding;
        const double d = depth(rng);
        const double cx = x0 + (k + 0.5) * len_x, cy = y0 + (k + 0.5) * len_y;
        scene.boxes.push_back({cls, {cx, y0 + 0.5 * d, 0.0}, len_x - 2.0, d, height(rng)});
        scene.boxes.push_back({cls, {cx, y1 - 0.5 * d, 0.0}, len_x - 2.0, d, height(rng)});
        scene.boxes.push_back({cls, {x0 + 0.5 * d, cy, 1.5707963}, len_y - 2.0, d, height(rng)});
        scene.boxes.push_back({cls, {x1 - 0.5 * d, cy, 1.5707963}, len_y - 2.0, d, height(rng)});
      }
    }
  scene.min_corner = {-half_road - sidewalk, -half_road - sidewalk};
  scene.max_corner = {size_x + half_road + sidewalk, size_y + half_road + sidewalk};
  return scene;
}

// A vehicle box in the right lane of a road along +x (y = lane_y), length 4.8, width 2.1.
inline Box car_at(double x, double y, double yaw = 0.0) {
  return Box{SemanticClass::kVehicle, {x, y, yaw}, 4.8, 2.1, 1.5};
}

}  // namespace indrive::env::testing
