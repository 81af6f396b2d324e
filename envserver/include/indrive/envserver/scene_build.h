// Turns a road network into the static scene the camera renders, and lists spawn points.
//
// Roads come from the lane shapes and junction polygons; sidewalks are strips along the road
// edges (and around junctions); road lines are the centre line between opposite directions,
// dashed lines between lanes of one direction and the road edge lines; buildings and some
// vegetation stand as boxes inside the blocks beyond the sidewalks. Deterministic for a seed.
//
//   StaticScene scene = build_static_scene(net, SceneOptions{});
//   std::vector<SpawnPoint> spawns = spawn_points(net);
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "indrive/envserver/net.h"
#include "indrive/envserver/scene.h"

namespace indrive::env {

// How the static scene is dressed.
struct SceneOptions {
  double sidewalk_width_m = 3.0;
  double line_width_m = 0.15;
  bool centre_line_dashed = false;   // solid centre line between opposite directions
  double building_setback_m = 1.0;   // gap between the sidewalk and the nearest box
  double building_cell_m = 14.0;     // footprint grid of the boxes inside blocks
  double vegetation_fraction = 0.3;  // share of box cells that hold vegetation, not buildings
  double margin_m = 40.0;            // how far beyond the roads boxes are placed
  std::uint32_t seed = 1;            // box heights and building / vegetation choice
};

// Builds the town's static scene: ground polygons in drawing order (sidewalks, then lanes and
// junctions), lines on top, boxes. The ground class where nothing is drawn is terrain-like
// vegetation.
StaticScene build_static_scene(const RoadNetwork& net, const SceneOptions& options = {});

// A place where a vehicle may start: on a normal lane, away from junctions.
struct SpawnPoint {
  Pose2 pose;           // on the lane centre, facing the direction of travel
  int lane = -1;        // index into RoadNetwork::lanes()
  std::string lane_id;  // SUMO lane id, e.g. for placing the vehicle in SUMO
  double s_m = 0.0;     // arc length on the lane
};

// Lists spawn points every `spacing_m` along every normal lane, keeping `junction_clearance_m`
// from both lane ends. Deterministic order (by lane, then by arc length).
std::vector<SpawnPoint> spawn_points(const RoadNetwork& net, double spacing_m = 15.0,
                                     double junction_clearance_m = 8.0);

}  // namespace indrive::env
