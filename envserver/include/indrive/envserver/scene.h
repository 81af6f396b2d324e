// The world as the semantic camera and the bird's-eye view see it.
//
// The road network (envserver/net.h) turns into a StaticScene once per town: flat ground
// polygons (road, sidewalk, terrain), road lines painted on the ground, and boxes (buildings,
// vegetation). Each step adds the moving boxes (vehicles, the ego excluded from its own
// camera) and the ego pose. World frame: SUMO's network coordinates, metres, x east, y north,
// z up; yaw in radians counter-clockwise from +x.
//
//   StaticScene scene = build_static_scene(net, SceneOptions{});
//   SemanticCamera camera(CameraConfig{.width = 128, .height = 128}, scene);
//   cv::Mat ids = camera.render(ego_pose, vehicles);   // CV_8UC1 class ids
//   cv::Mat rgb = colorize(ids);                        // CV_8UC3, CARLA palette (RGB order)
#pragma once

#include <array>
#include <cstdint>
#include <string_view>
#include <vector>

#include <Eigen/Core>

namespace indrive::env {

// Semantic classes; the ids are what observations carry (1 byte per pixel).
enum class SemanticClass : std::uint8_t {
  kUnlabeled = 0,
  kRoad = 1,
  kRoadLine = 2,
  kSidewalk = 3,
  kVehicle = 4,
  kBuilding = 5,
  kVegetation = 6,
  kSky = 7,
};
inline constexpr int kNumSemanticClasses = 8;

// CARLA palette, RGB order, indexed by SemanticClass.
inline constexpr std::array<std::array<std::uint8_t, 3>, kNumSemanticClasses> kPaletteRgb = {{
    {0, 0, 0},        // unlabeled
    {128, 64, 128},   // road
    {157, 234, 50},   // road line
    {244, 35, 232},   // sidewalk
    {0, 0, 142},      // vehicle
    {70, 70, 70},     // building
    {107, 142, 35},   // vegetation
    {70, 130, 180},   // sky
}};

std::string_view class_name(SemanticClass cls);

// A planar pose on the ground.
struct Pose2 {
  double x_m = 0.0;
  double y_m = 0.0;
  double yaw_rad = 0.0;
};

// A polygon lying flat on the ground (z = 0), e.g. a lane surface or a sidewalk strip.
// Polygons are drawn in the order given: later ones cover earlier ones where they overlap.
struct GroundPolygon {
  SemanticClass cls = SemanticClass::kRoad;
  std::vector<Eigen::Vector2d> points;  // closed implicitly, any orientation, simple polygon
};

// A painted line on the ground (lane marking or road edge), as a polyline of given width.
struct GroundLine {
  std::vector<Eigen::Vector2d> points;
  double width_m = 0.15;
  bool dashed = false;  // 3 m painted, 6 m gap, as on urban roads
};

// An upright box standing on the ground: a vehicle, a building, a block of vegetation.
struct Box {
  SemanticClass cls = SemanticClass::kVehicle;
  Pose2 pose;             // centre of the footprint and heading of the long side
  double length_m = 4.8;  // along the heading
  double width_m = 2.1;
  double height_m = 1.5;
};

// Everything that does not move, built once per town.
struct StaticScene {
  SemanticClass ground_class = SemanticClass::kVegetation;  // fills the ground nothing covers
  std::vector<GroundPolygon> ground;                          // drawn in order
  std::vector<GroundLine> lines;                              // drawn on top of the ground
  std::vector<Box> boxes;                                     // buildings, vegetation
  Eigen::Vector2d min_corner{0.0, 0.0};                       // bounding box of the scene
  Eigen::Vector2d max_corner{0.0, 0.0};
};

}  // namespace indrive::env
