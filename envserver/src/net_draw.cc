// Drawing a town with its routes and spawn points to a PNG.
#include <algorithm>
#include <cmath>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "indrive/envserver/net_geometry.h"
#include "indrive/envserver/town.h"

namespace indrive::env {

namespace {

// BGR colours, one per route in kRouteNames order, then more for extra routes.
const cv::Scalar kRouteColours[] = {{255, 170, 0},  {0, 140, 255}, {60, 220, 60},
                                    {220, 60, 220}, {0, 220, 220}, {200, 200, 80}};

class Canvas {
 public:
  Canvas(const Eigen::Vector2d& lo, const Eigen::Vector2d& hi, double pixels_per_m)
      : lo_(lo), hi_(hi), scale_(pixels_per_m) {}
  cv::Size size() const {
    return {static_cast<int>(std::ceil((hi_.x() - lo_.x()) * scale_)),
            static_cast<int>(std::ceil((hi_.y() - lo_.y()) * scale_))};
  }
  // North up: image rows grow southwards. Fixed-point coordinates (shift 3) for smooth lines.
  cv::Point px(const Eigen::Vector2d& p) const {
    return {static_cast<int>(std::lround((p.x() - lo_.x()) * scale_ * 8.0)),
            static_cast<int>(std::lround((hi_.y() - p.y()) * scale_ * 8.0))};
  }
  cv::Point px_int(const Eigen::Vector2d& p) const {
    const cv::Point q = px(p);
    return {q.x / 8, q.y / 8};
  }
  std::vector<cv::Point> px(const std::vector<Eigen::Vector2d>& points) const {
    std::vector<cv::Point> out;
    for (const auto& p : points) out.push_back(px(p));
    return out;
  }
  double scale() const { return scale_; }

 private:
  Eigen::Vector2d lo_, hi_;
  double scale_;
};

std::vector<Eigen::Vector2d> lane_polygon(const Lane& lane) {
  auto left = geometry::offset_polyline(lane.shape, 0.5 * lane.width_m);
  auto right = geometry::offset_polyline(lane.shape, -0.5 * lane.width_m);
  left.insert(left.end(), right.rbegin(), right.rend());
  return left;
}

}  // namespace

void draw_town(const RoadNetwork& net, const std::vector<Route>& routes,
               const std::vector<SpawnPoint>& spawns, const std::filesystem::path& png_path,
               double pixels_per_m) {
  const double margin = 12.0;
  const double legend_m = 24.0 + 7.0 * routes.size() / std::max(pixels_per_m / 2.5, 0.5);
  const Eigen::Vector2d lo = net.min_corner() - Eigen::Vector2d(margin, margin + legend_m);
  const Eigen::Vector2d hi = net.max_corner() + Eigen::Vector2d(margin, margin);
  const Canvas canvas(lo, hi, pixels_per_m);
  cv::Mat image(canvas.size(), CV_8UC3, cv::Scalar(52, 78, 52));

  // Roads: junction areas and lanes in grey, lane centres faintly, direction ticks.
  const cv::Scalar road(105, 105, 105);
  for (const Junction& junction : net.junctions()) {
    if (junction.shape.size() < 3) continue;
    std::vector<std::vector<cv::Point>> polygon = {canvas.px(junction.shape)};
    cv::fillPoly(image, polygon, road, cv::LINE_AA, 3);
  }
  for (const Lane& lane : net.lanes()) {
    std::vector<std::vector<cv::Point>> polygon = {canvas.px(lane_polygon(lane))};
    cv::fillPoly(image, polygon, road, cv::LINE_AA, 3);
  }
  for (const Lane& lane : net.lanes()) {
    if (lane.internal) continue;
    cv::polylines(image, canvas.px(lane.shape), false, cv::Scalar(150, 150, 150), 1, cv::LINE_AA,
                  3);
  }

  // Spawn points: small white dots with a short stroke showing the heading.
  for (const SpawnPoint& spawn : spawns) {
    const Eigen::Vector2d p(spawn.pose.x_m, spawn.pose.y_m);
    const Eigen::Vector2d tip =
        p + 2.5 * Eigen::Vector2d(std::cos(spawn.pose.yaw_rad), std::sin(spawn.pose.yaw_rad));
    cv::line(image, canvas.px(p), canvas.px(tip), cv::Scalar(235, 235, 235), 1, cv::LINE_AA, 3);
    cv::circle(image, canvas.px(p), 8 * 1, cv::Scalar(235, 235, 235), cv::FILLED, cv::LINE_AA, 3);
  }

  // Routes: each in its own colour, shifted sideways a little so overlapping routes stay
  // visible; then, on top of all lines, arrows every 40 m, a ring at each start and a cross at
  // the end of a point-to-point route.
  const int thickness = std::max(2, static_cast<int>(std::lround(0.8 * canvas.scale())));
  std::vector<std::vector<Eigen::Vector2d>> lines;
  for (size_t r = 0; r < routes.size(); ++r) {
    const double shift = (static_cast<double>(r) - 1.5) * 0.6;
    std::vector<Eigen::Vector2d> line;
    for (const Waypoint& w : routes[r].waypoints()) {
      line.push_back(w.position +
                     shift * Eigen::Vector2d(-std::sin(w.heading_rad), std::cos(w.heading_rad)));
    }
    cv::polylines(image, canvas.px(line), routes[r].is_loop(),
                  kRouteColours[r % std::size(kRouteColours)], thickness, cv::LINE_AA, 3);
    lines.push_back(std::move(line));
  }
  for (size_t r = 0; r < routes.size(); ++r) {
    const Route& route = routes[r];
    const std::vector<Eigen::Vector2d>& line = lines[r];
    const cv::Scalar colour = kRouteColours[r % std::size(kRouteColours)];
    const int arrow_every =
        std::max(1, static_cast<int>(40.0 / (route.length_m() / route.waypoints().size())));
    for (size_t i = arrow_every / 2; i + 2 < line.size(); i += arrow_every) {
      cv::arrowedLine(image, canvas.px(line[i]), canvas.px(line[i + 2]), colour, thickness,
                      cv::LINE_AA, 3, 1.0);
    }
    cv::circle(image, canvas.px(line.front()), static_cast<int>(8 * 2.5 * canvas.scale()), colour,
               thickness, cv::LINE_AA, 3);
    if (!route.is_loop()) {
      cv::drawMarker(image, canvas.px_int(line.back()), colour, cv::MARKER_TILTED_CROSS,
                     static_cast<int>(5 * canvas.scale()), thickness, cv::LINE_AA);
    }
  }

  // Legend along the bottom.
  const double font = std::max(0.4, 0.18 * canvas.scale());
  int y = image.rows - static_cast<int>(8 * font) - 4;
  for (size_t r = routes.size(); r-- > 0;) {
    const cv::Scalar colour = kRouteColours[r % std::size(kRouteColours)];
    char text[128];
    std::snprintf(text, sizeof text, "%s (%s, %.0f m)", routes[r].name().c_str(),
                  routes[r].is_loop() ? "loop" : "point to point", routes[r].length_m());
    cv::line(image, {10, y - static_cast<int>(5 * font)}, {40, y - static_cast<int>(5 * font)},
             colour, 3, cv::LINE_AA);
    cv::putText(image, text, {48, y}, cv::FONT_HERSHEY_SIMPLEX, font, cv::Scalar(240, 240, 240), 1,
                cv::LINE_AA);
    y -= static_cast<int>(28 * font) + 4;
  }
  char header[160];
  std::snprintf(header, sizeof header, "%zu spawn points (white); ring = route start, x = end",
                spawns.size());
  cv::putText(image, header, {10, y}, cv::FONT_HERSHEY_SIMPLEX, font, cv::Scalar(240, 240, 240), 1,
              cv::LINE_AA);

  std::error_code ec;
  if (png_path.has_parent_path()) std::filesystem::create_directories(png_path.parent_path(), ec);
  bool written = false;
  try {
    written = cv::imwrite(png_path.string(), image);
  } catch (const cv::Exception& error) {
    written = false;
  }
  if (!written) {
    throw MapError("cannot write the town drawing to '" + png_path.string() +
                   "'; check the folder exists and is writable and the name ends in .png");
  }
}

}  // namespace indrive::env
