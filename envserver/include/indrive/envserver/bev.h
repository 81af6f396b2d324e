// Bird's-eye view: a top-down image of the semantic classes around the ego, for videos and
// debugging. The ego points up; it is drawn in white with a heading notch so it stands out
// from the other vehicles.
//
//   BirdsEyeView bev(BevConfig{}, cache);           // cache: shared SceneCache of the town
//   cv::Mat rgb = bev.render(ego_box, vehicles, {.route = route_points, .alert = collided});
#pragma once

#include <Eigen/Core>
#include <memory>
#include <opencv2/core.hpp>
#include <span>

#include "indrive/envserver/camera.h"
#include "indrive/envserver/scene.h"

namespace indrive::env {

// Size and placement of the bird's-eye view.
struct BevConfig {
  int size_px = 256;               // square image side
  double extent_m = 40.0;          // world distance covered by the image side
  double ego_row_fraction = 0.65;  // ego's image row as a fraction of the height (0 = top)
};

// Throws CameraError naming the first field that is out of range.
void validate(const BevConfig& config);

// What is drawn on top of the classes in render().
struct BevOverlay {
  std::span<const Eigen::Vector2d> route;  // world polyline (x, y) in metres; may be empty
  bool alert = false;                      // draws the ego in red (e.g. an event fired)
};

// Renders the classes around the ego from above.
class BirdsEyeView {
 public:
  // Builds the view on a shared scene cache; throws CameraError for a bad config.
  BirdsEyeView(const BevConfig& config, std::shared_ptr<const SceneCache> scene);
  // Convenience: builds a private SceneCache of the scene with default options.
  BirdsEyeView(const BevConfig& config, const StaticScene& scene);

  // Class ids (no ego marker, no route): CV_8UC1 (size_px, size_px); the ego box is drawn as a
  // vehicle like the others. class_ids is reallocated only if its size or type differ.
  void render_classes(const Box& ego, std::span<const Box> vehicles, cv::Mat& class_ids) const;
  // Colour image: CV_8UC3 (size_px, size_px, 3), RGB order, CARLA palette, with the route in
  // yellow and the ego in white (red when overlay.alert) with a heading notch.
  cv::Mat render(const Box& ego, std::span<const Box> vehicles,
                 const BevOverlay& overlay = {}) const;

  // Image position (column, row) of a world point for the given ego pose.
  Eigen::Vector2d to_pixel(const Pose2& ego, const Eigen::Vector2d& world) const;

  const BevConfig& config() const { return config_; }

 private:
  BevConfig config_;
  std::shared_ptr<const SceneCache> scene_;
  mutable std::vector<int> candidates_;  // scratch static box indices
};

}  // namespace indrive::env
