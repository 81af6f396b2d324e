// The semantic camera: a front-mounted pinhole camera that renders class ids (CARLA classes).
//
// How it renders (chosen for speed; figures from tests/envserver/camera_bench.cc):
// - Ground by inverse perspective. The static ground (road, sidewalk, painted lines) is
//   rasterised once per town into a top-down class map (SceneCache, 0.1 m per cell). Each frame,
//   every pixel below the horizon is intersected with the flat ground and looks its class up in
//   that map. Along one image row the ground point is affine in the column, so this costs a few
//   additions per pixel.
// - Thin lines. A painted line far away is narrower than a pixel; nearest lookup would make it
//   flicker in and out. Rule: a road line is drawn wherever it crosses the pixel's lateral
//   ground footprint, so lane markings stay at least one pixel wide at any distance. The map
//   keeps a pyramid of "a line crosses this cell" bits; each image row uses the level with the
//   smallest cells at least as wide as its lateral footprint, so lines show one to two pixels
//   wide. Lines seen end-on across the view (stop lines far ahead) can still fall between rows.
// - Boxes (buildings, vegetation, vehicles) are clipped in 3D against the near plane, projected
//   and scan-filled into a per-pixel 1/z buffer, so they occlude each other exactly. Upright
//   boxes on flat ground always hide the ground behind them. Static boxes come from a grid
//   index and are culled against the view frustum; only the moving boxes are new each frame.
//
//   auto cache = std::make_shared<const SceneCache>(scene);
//   SemanticCamera camera(CameraConfig{.width = 64, .height = 64}, cache);
//   cv::Mat ids;                             // reused every step, no allocation after the first
//   camera.render(ego_pose, vehicles, ids);  // CV_8UC1 (H, W) class ids
//   cv::Mat rgb = colorize(ids);             // CV_8UC3 (H, W, 3), CARLA palette, RGB order
#pragma once

#include <Eigen/Core>
#include <memory>
#include <opencv2/core.hpp>
#include <optional>
#include <span>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "indrive/envserver/scene.h"

namespace indrive::env {

// A camera or scene setting that cannot work (thrown at construction, never while rendering).
class CameraError : public std::invalid_argument {
 public:
  using std::invalid_argument::invalid_argument;
};

// Where the camera sits on the ego and what it sees. Defaults follow the paper's CARLA setup.
struct CameraConfig {
  int width = 128;         // pixels; the preset's image size, rendered directly
  int height = 128;        // pixels
  double hfov_deg = 90.0;  // horizontal field of view; square pixels
  double forward_m = 1.5;  // mount point ahead of the ego's footprint centre
  double height_m = 2.4;   // mount point above the ground
  double pitch_deg = 0.0;  // positive looks down
  double near_m = 0.05;    // near clipping plane (camera depth)
  double far_m = 120.0;    // ground beyond this camera depth shows ground_class; boxes
                           // entirely beyond it are skipped
};

// Throws CameraError naming the first field that is out of range.
void validate(const CameraConfig& config);

// Options of the precomputed static scene.
struct SceneCacheOptions {
  double resolution_m = 0.1;            // ground map cell size
  double margin_m = 20.0;               // ground map border around the scene bounds
  std::int64_t max_cells = 64'000'000;  // bytes of map per process; larger maps are
                                        // coarsened by doubling resolution_m
  double box_grid_cell_m = 32.0;        // cell size of the static box index
};

// The static scene prepared for fast rendering: the top-down ground class map, its road-line
// pyramid and a grid index of the static boxes. Built once per town and shared (read-only,
// thread-safe) by every camera and bird's-eye view of that town.
class SceneCache {
 public:
  // Rasterises the ground and indexes the boxes; throws CameraError for a scene with
  // non-finite coordinates or bounds that would need more than options.max_cells even at 1 m.
  explicit SceneCache(const StaticScene& scene, const SceneCacheOptions& options = {});

  // Class of the ground at a world point (nearest cell); ground_class outside the map.
  SemanticClass ground_at(double x_m, double y_m) const;
  // Class of the ground seen by a pixel whose ground footprint is footprint_m wide: a road line
  // that crosses the footprint wins, otherwise the class at the point.
  SemanticClass ground_seen(double x_m, double y_m, double footprint_m) const;

  // The ground class map, CV_8UC1 (rows, cols); row 0 is the northern edge (max y).
  const cv::Mat& ground_map() const { return levels_[0]; }
  // Line pyramid level l (l >= 1), CV_8UC1 (rows >> l, cols >> l), nonzero where a line
  // crosses the 2^l x 2^l block of base cells.
  const cv::Mat& line_level(int level) const { return levels_[level]; }
  int num_levels() const { return static_cast<int>(levels_.size()); }
  // The pyramid level with the smallest cells at least footprint_m wide (0 below one cell).
  int line_level_for(double footprint_m) const;
  double resolution_m() const { return resolution_m_; }
  // World coordinates of the map's north-west corner (min x, max y).
  Eigen::Vector2d origin() const { return origin_; }

  SemanticClass ground_class() const { return ground_class_; }
  const std::vector<Box>& boxes() const { return boxes_; }
  // Appends to out the indices of static boxes whose footprint may overlap the axis-aligned
  // world rectangle [min, max]; each index once, in increasing order.
  void boxes_in(const Eigen::Vector2d& min, const Eigen::Vector2d& max,
                std::vector<int>& out) const;

 private:
  void rasterise_ground(const StaticScene& scene, int rows, int cols);
  void build_line_pyramid(const cv::Mat& line_mask);
  void index_boxes(double cell_m);
  std::pair<int, int> cell_of(const Eigen::Vector2d& p) const;  // (col, row), clamped

  SemanticClass ground_class_;
  double resolution_m_ = 0.1;
  Eigen::Vector2d origin_{0.0, 0.0};
  std::vector<cv::Mat> levels_;  // [0] classes, [1..] line bits
  std::vector<Box> boxes_;
  double box_cell_m_ = 32.0;
  Eigen::Vector2d box_grid_min_{0.0, 0.0};
  int box_grid_cols_ = 0;
  int box_grid_rows_ = 0;
  std::vector<std::vector<int>> box_grid_;  // row-major cells of box indices
};

// A front-mounted pinhole camera that renders class ids.
// One instance is not safe to call from two threads at once (it keeps scratch buffers);
// use one camera per environment.
class SemanticCamera {
 public:
  // Builds the camera on a shared scene cache; throws CameraError for a bad config.
  SemanticCamera(const CameraConfig& config, std::shared_ptr<const SceneCache> scene);
  // Convenience: builds a private SceneCache of the scene with default options.
  SemanticCamera(const CameraConfig& config, const StaticScene& scene);

  // Renders the view from the ego pose. vehicles are the other vehicles' boxes in the world
  // frame (the ego itself excluded). class_ids becomes CV_8UC1 (height, width) of
  // SemanticClass values; it is reallocated only if its size or type differ.
  void render(const Pose2& ego, std::span<const Box> vehicles, cv::Mat& class_ids) const;
  // Same, returning a new image.
  cv::Mat render(const Pose2& ego, std::span<const Box> vehicles) const;

  // Pixel coordinates (u right, v down; pixel (i, j) covers [i, i+1) x [j, j+1)) of a world
  // point (x, y, z) seen from the ego pose, or nothing if it lies behind the near plane.
  std::optional<Eigen::Vector2d> project(const Pose2& ego, const Eigen::Vector3d& world) const;

  const CameraConfig& config() const { return config_; }
  const SceneCache& scene() const { return *scene_; }

 private:
  CameraConfig config_;
  std::shared_ptr<const SceneCache> scene_;
  double focal_px_ = 0.0;
  // Per image row, in the ego frame: ground point of column 0's centre and its step per
  // column, or no ground (row at or above the horizon). Constant because the camera has no
  // roll, so one row of rays meets the ground along a straight line at one depth.
  struct RowGround {
    enum class Kind : std::uint8_t { kSky, kBeyondFar, kGround } kind = Kind::kSky;
    double forward_m = 0.0;  // ground point of pixel centre (0, row), ego frame
    double left0_m = 0.0;
    double step_forward_m = 0.0;  // change per column (zero without roll, kept for clarity)
    double step_left_m = 0.0;
    int line_level = 0;  // line pyramid level matching this row's lateral footprint
  };
  std::vector<RowGround> rows_;
  mutable std::vector<float> inv_depth_;  // (height * width) scratch 1/z buffer
  mutable std::vector<int> candidates_;   // scratch static box indices
};

// Returns the RGB image (CARLA palette, RGB channel order) of a class-id image.
// class_ids is CV_8UC1 (H, W); the result is CV_8UC3 (H, W, 3). Ids out of range map to
// unlabeled. Convert with cv::cvtColor(rgb, bgr, cv::COLOR_RGB2BGR) before cv::imwrite.
cv::Mat colorize(const cv::Mat& class_ids);
// Same, writing into rgb (reallocated only if its size or type differ).
void colorize(const cv::Mat& class_ids, cv::Mat& rgb);

}  // namespace indrive::env
