// Bird's-eye view: ground classes looked up in the scene cache's top-down map, boxes filled as
// rotated rectangles, then the route and a distinct ego marker for the colour image.
#include "indrive/envserver/bev.h"

#include <cmath>
#include <opencv2/imgproc.hpp>

#include "camera_geometry.h"
#include "indrive/basics/check.h"

namespace indrive::env {
namespace {

constexpr int kShift = 4;  // fractional bits of OpenCV fill coordinates
constexpr double kShiftScale = 1 << kShift;

// Image placement of the ego: pixel coordinates of the ego centre and metres per pixel.
struct Placement {
  double col, row, metres_per_px, cos_yaw, sin_yaw;
  Pose2 ego;

  // Continuous image coordinates (column, row) of a world point; pixel i covers [i, i+1).
  Eigen::Vector2d to_pixel(const Eigen::Vector2d& world) const {
    const double dx = world.x() - ego.x_m, dy = world.y() - ego.y_m;
    const double forward = cos_yaw * dx + sin_yaw * dy;
    const double left = -sin_yaw * dx + cos_yaw * dy;
    return {col - left / metres_per_px, row - forward / metres_per_px};
  }
  // OpenCV fill coordinates (pixel centres at integers, kShift fractional bits).
  cv::Point to_fill(const Eigen::Vector2d& world) const {
    const Eigen::Vector2d p = to_pixel(world) - Eigen::Vector2d(0.5, 0.5);
    return {static_cast<int>(std::lround(p.x() * kShiftScale)),
            static_cast<int>(std::lround(p.y() * kShiftScale))};
  }
};

Placement place(const BevConfig& config, const Pose2& ego) {
  return Placement{0.5 * config.size_px,
                   config.ego_row_fraction * config.size_px,
                   config.extent_m / config.size_px,
                   std::cos(ego.yaw_rad),
                   std::sin(ego.yaw_rad),
                   ego};
}

void fill_box(const Placement& at, const Box& box, const cv::Scalar& colour, cv::Mat& image) {
  const auto corners = detail::footprint(box);
  cv::Point points[4];
  for (int k = 0; k < 4; ++k) points[k] = at.to_fill(corners[k]);
  cv::fillConvexPoly(image, points, 4, colour, cv::LINE_8, kShift);
}

}  // namespace

BirdsEyeView::BirdsEyeView(const BevConfig& config, const StaticScene& scene)
    : BirdsEyeView(config, std::make_shared<const SceneCache>(scene)) {}

BirdsEyeView::BirdsEyeView(const BevConfig& config, std::shared_ptr<const SceneCache> scene)
    : config_(config), scene_(std::move(scene)) {
  validate(config_);
  INDRIVE_CHECK(scene_ != nullptr) << "BirdsEyeView needs a scene cache";
}

Eigen::Vector2d BirdsEyeView::to_pixel(const Pose2& ego, const Eigen::Vector2d& world) const {
  return place(config_, ego).to_pixel(world);
}

void BirdsEyeView::render_classes(const Box& ego, std::span<const Box> vehicles,
                                  cv::Mat& class_ids) const {
  const int size = config_.size_px;
  class_ids.create(size, size, CV_8UC1);
  const Placement at = place(config_, ego.pose);
  const SceneCache& scene = *scene_;

  // Ground: each pixel centre's world point, looked up with the pixel's size as footprint so
  // painted lines stay visible when a pixel is wider than a line. Map coordinates are affine
  // along a row, as in the camera.
  const double mpp = at.metres_per_px;
  const cv::Mat& base = scene.ground_map();
  const int level = scene.line_level_for(mpp);
  const cv::Mat& lines = scene.line_level(level);
  const double res = scene.resolution_m();
  const Eigen::Vector2d origin = scene.origin();
  const std::uint8_t fallback = static_cast<std::uint8_t>(scene.ground_class());
  const std::uint8_t road_line = static_cast<std::uint8_t>(SemanticClass::kRoadLine);
  // One column step is one pixel to the right, i.e. mpp metres along -left.
  const double col_step = at.sin_yaw * mpp / res;
  const double row_step = at.cos_yaw * mpp / res;
  for (int row = 0; row < size; ++row) {
    std::uint8_t* out = class_ids.ptr<std::uint8_t>(row);
    const double forward = (at.row - (row + 0.5)) * mpp;
    const double left = (at.col - 0.5) * mpp;
    const double x0 = ego.pose.x_m + at.cos_yaw * forward - at.sin_yaw * left;
    const double y0 = ego.pose.y_m + at.sin_yaw * forward + at.cos_yaw * left;
    const double col0 = (x0 - origin.x()) / res, row0 = (origin.y() - y0) / res;
    for (int col = 0; col < size; ++col) {
      const double mc = col0 + col * col_step, mr = row0 + col * row_step;
      if (!(mc >= 0.0 && mr >= 0.0 && mc < base.cols && mr < base.rows)) {
        out[col] = fallback;
        continue;
      }
      const int ci = static_cast<int>(mc), ri = static_cast<int>(mr);
      out[col] = level > 0 && lines.ptr<std::uint8_t>(ri >> level)[ci >> level] != 0
                     ? road_line
                     : base.ptr<std::uint8_t>(ri)[ci];
    }
  }

  // Static boxes near the view (the view's circumscribed square), then vehicles and the ego.
  const double reach = config_.extent_m * std::sqrt(2.0);
  const Eigen::Vector2d centre(ego.pose.x_m, ego.pose.y_m);
  candidates_.clear();
  scene.boxes_in(centre.array() - reach, centre.array() + reach, candidates_);
  for (const int index : candidates_) {
    const Box& box = scene.boxes()[index];
    fill_box(at, box, cv::Scalar(static_cast<int>(box.cls)), class_ids);
  }
  for (const Box& vehicle : vehicles)
    fill_box(at, vehicle, cv::Scalar(static_cast<int>(vehicle.cls)), class_ids);
  fill_box(at, ego, cv::Scalar(static_cast<int>(ego.cls)), class_ids);
}

cv::Mat BirdsEyeView::render(const Box& ego, std::span<const Box> vehicles,
                             const BevOverlay& overlay) const {
  cv::Mat class_ids;
  render_classes(ego, vehicles, class_ids);
  cv::Mat rgb = colorize(class_ids);
  const Placement at = place(config_, ego.pose);

  // Route: a yellow polyline, anti-aliased so it reads well at any scale.
  if (overlay.route.size() >= 2) {
    std::vector<cv::Point> points;
    points.reserve(overlay.route.size());
    for (const Eigen::Vector2d& p : overlay.route) points.push_back(at.to_fill(p));
    cv::polylines(rgb, points, false, cv::Scalar(255, 220, 0), 2, cv::LINE_AA, kShift);
  }

  // Ego: white (red on alert), outside the palette so it stands out, with a dark notch
  // at the front showing the heading.
  const cv::Scalar ego_colour = overlay.alert ? cv::Scalar(255, 0, 0) : cv::Scalar(255, 255, 255);
  fill_box(at, ego, ego_colour, rgb);
  const auto corners = detail::footprint(ego);
  const Eigen::Vector2d front_mid = 0.5 * (corners[1] + corners[2]);
  const Eigen::Vector2d centre(ego.pose.x_m, ego.pose.y_m);
  const Eigen::Vector2d notch_base = centre + 0.55 * (front_mid - centre);
  const Eigen::Vector2d half_across = 0.35 * (corners[2] - corners[1]);
  const cv::Point notch[3] = {at.to_fill(front_mid), at.to_fill(notch_base + half_across),
                              at.to_fill(notch_base - half_across)};
  cv::fillConvexPoly(rgb, notch, 3, cv::Scalar(40, 40, 40), cv::LINE_AA, kShift);
  return rgb;
}

}  // namespace indrive::env
