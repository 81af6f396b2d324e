// The static scene prepared once per town: a top-down ground class map with a road-line
// pyramid, and a grid index of the static boxes (see camera.h for why).
#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <opencv2/imgproc.hpp>
#include <sstream>

#include "camera_geometry.h"
#include "indrive/basics/check.h"
#include "indrive/basics/log.h"
#include "indrive/envserver/camera.h"

namespace indrive::env {
namespace {

// Sub-pixel precision of the OpenCV fills (coordinates carry 4 fractional bits).
constexpr int kShift = 4;
constexpr double kShiftScale = 1 << kShift;
// Coarsest pyramid cell: a footprint wider than this still uses this level.
constexpr double kCoarsestLineCellM = 6.4;
// Dashed lines: painted length and period along the line, as on urban roads (scene.h).
constexpr double kDashOnM = 3.0;
constexpr double kDashPeriodM = 9.0;

struct Bounds {
  Eigen::Vector2d min{std::numeric_limits<double>::infinity(),
                      std::numeric_limits<double>::infinity()};
  Eigen::Vector2d max{-std::numeric_limits<double>::infinity(),
                      -std::numeric_limits<double>::infinity()};
  void add(const Eigen::Vector2d& p) {
    min = min.cwiseMin(p);
    max = max.cwiseMax(p);
  }
  bool empty() const { return !(min.x() <= max.x() && min.y() <= max.y()); }
};

void require_finite(const Eigen::Vector2d& p, const char* what) {
  if (!std::isfinite(p.x()) || !std::isfinite(p.y())) {
    std::ostringstream message;
    message << "static scene has a non-finite " << what << " coordinate (" << p.x() << ", " << p.y()
            << "); fix the road network or scene builder that produced it";
    throw CameraError(message.str());
  }
}

using detail::footprint;

}  // namespace

SceneCache::SceneCache(const StaticScene& scene, const SceneCacheOptions& options)
    : ground_class_(scene.ground_class), boxes_(scene.boxes) {
  if (!(options.resolution_m > 0.0) || !(options.margin_m >= 0.0) || options.max_cells < 1 ||
      !(options.box_grid_cell_m > 0.0)) {
    throw CameraError(
        "scene cache options out of range: need resolution_m > 0, margin_m >= 0, max_cells >= 1, "
        "box_grid_cell_m > 0");
  }

  // Bounds: the scene's own plus everything in it, so a scene with unset bounds still works.
  Bounds bounds;
  if (scene.min_corner != scene.max_corner) {
    require_finite(scene.min_corner, "bounds");
    require_finite(scene.max_corner, "bounds");
    bounds.add(scene.min_corner);
    bounds.add(scene.max_corner);
  }
  for (const GroundPolygon& polygon : scene.ground)
    for (const Eigen::Vector2d& p : polygon.points) {
      require_finite(p, "ground polygon");
      bounds.add(p);
    }
  for (const GroundLine& line : scene.lines)
    for (const Eigen::Vector2d& p : line.points) {
      require_finite(p, "road line");
      bounds.add(p);
    }
  for (const Box& box : scene.boxes)
    for (const Eigen::Vector2d& p : footprint(box)) {
      require_finite(p, "box");
      bounds.add(p);
    }
  if (bounds.empty()) bounds.add(Eigen::Vector2d::Zero());
  bounds.min.array() -= options.margin_m;
  bounds.max.array() += options.margin_m;

  // Resolution: coarsen until the map fits the cell budget.
  resolution_m_ = options.resolution_m;
  const Eigen::Vector2d size = bounds.max - bounds.min;
  auto cells = [&](double res) { return std::ceil(size.x() / res) * std::ceil(size.y() / res); };
  while (cells(resolution_m_) > static_cast<double>(options.max_cells)) {
    if (resolution_m_ >= 1.0) {
      std::ostringstream message;
      message << "static scene spans " << size.x() << " x " << size.y()
              << " m, too large for a ground map of " << options.max_cells
              << " cells even at 1 m; raise SceneCacheOptions::max_cells or crop the map";
      throw CameraError(message.str());
    }
    resolution_m_ *= 2.0;
  }
  if (resolution_m_ != options.resolution_m) {
    INDRIVE_LOG(kWarn, "camera") << "ground map coarsened to " << resolution_m_
                                 << " m per cell to fit " << options.max_cells << " cells";
  }
  origin_ = Eigen::Vector2d(bounds.min.x(), bounds.max.y());
  const int cols = static_cast<int>(std::ceil(size.x() / resolution_m_));
  const int rows = static_cast<int>(std::ceil(size.y() / resolution_m_));

  rasterise_ground(scene, rows, cols);
  index_boxes(options.box_grid_cell_m);
}

void SceneCache::rasterise_ground(const StaticScene& scene, int rows, int cols) {
  // OpenCV puts pixel centres at integer coordinates; our cell (i, j) covers [i, i+1) in map
  // units, so points shift by half a cell. Coordinates carry kShift fractional bits.
  auto to_fill = [&](const Eigen::Vector2d& p) {
    const double col = (p.x() - origin_.x()) / resolution_m_ - 0.5;
    const double row = (origin_.y() - p.y()) / resolution_m_ - 0.5;
    return cv::Point(static_cast<int>(std::lround(col * kShiftScale)),
                     static_cast<int>(std::lround(row * kShiftScale)));
  };

  // Ground polygons, later ones over earlier ones.
  cv::Mat classes(rows, cols, CV_8UC1, cv::Scalar(static_cast<int>(ground_class_)));
  std::vector<cv::Point> pixels;
  for (const GroundPolygon& polygon : scene.ground) {
    if (polygon.points.size() < 3) continue;
    pixels.clear();
    for (const Eigen::Vector2d& p : polygon.points) pixels.push_back(to_fill(p));
    const cv::Point* contours[] = {pixels.data()};
    const int counts[] = {static_cast<int>(pixels.size())};
    cv::fillPoly(classes, contours, counts, 1, cv::Scalar(static_cast<int>(polygon.cls)),
                 cv::LINE_8, kShift);
  }

  // Road lines into a separate mask (the pyramid needs it), as quads per segment and discs at
  // the joints so bends have no gaps; dashes follow the arc length.
  cv::Mat line_mask(rows, cols, CV_8UC1, cv::Scalar(0));
  auto paint_piece = [&](const std::vector<Eigen::Vector2d>& piece, double half_width_m) {
    for (std::size_t k = 0; k + 1 < piece.size(); ++k) {
      const Eigen::Vector2d d = piece[k + 1] - piece[k];
      const double length = d.norm();
      if (length <= 0.0) continue;
      const Eigen::Vector2d n = Eigen::Vector2d(-d.y(), d.x()) * (half_width_m / length);
      const cv::Point quad[] = {to_fill(piece[k] + n), to_fill(piece[k + 1] + n),
                                to_fill(piece[k + 1] - n), to_fill(piece[k] - n)};
      cv::fillConvexPoly(line_mask, quad, 4, cv::Scalar(255), cv::LINE_8, kShift);
      if (k > 0) {
        const int radius =
            static_cast<int>(std::lround(half_width_m / resolution_m_ * kShiftScale));
        cv::circle(line_mask, to_fill(piece[k]), radius, cv::Scalar(255), cv::FILLED, cv::LINE_8,
                   kShift);
      }
    }
  };
  std::vector<Eigen::Vector2d> piece;
  for (const GroundLine& line : scene.lines) {
    if (line.points.size() < 2 || !(line.width_m > 0.0)) continue;
    const double half_width = 0.5 * line.width_m;
    if (!line.dashed) {
      paint_piece(line.points, half_width);
      continue;
    }
    // Walk the polyline, emitting the painted stretches [0, kDashOnM) of every period.
    double s = 0.0;  // arc length at the start of the current segment
    piece.clear();
    for (std::size_t k = 0; k + 1 < line.points.size(); ++k) {
      const Eigen::Vector2d a = line.points[k];
      const Eigen::Vector2d d = line.points[k + 1] - a;
      const double length = d.norm();
      if (length <= 0.0) continue;
      double t = 0.0;  // distance along this segment
      while (t < length) {
        const double phase = std::fmod(s + t, kDashPeriodM);
        const bool painted = phase < kDashOnM;
        const double to_switch = painted ? kDashOnM - phase : kDashPeriodM - phase;
        const double t_end = std::min(length, t + to_switch);
        if (painted) {
          if (piece.empty()) piece.push_back(a + d * (t / length));
          piece.push_back(a + d * (t_end / length));
          if (t_end < length) {  // the dash ends inside this segment
            paint_piece(piece, half_width);
            piece.clear();
          }
        }
        t = t_end + 1e-9;
      }
      s += length;
    }
    if (piece.size() >= 2) paint_piece(piece, half_width);
  }
  classes.setTo(cv::Scalar(static_cast<int>(SemanticClass::kRoadLine)), line_mask);

  levels_.clear();
  levels_.push_back(classes);
  build_line_pyramid(line_mask);
}

void SceneCache::build_line_pyramid(const cv::Mat& line_mask) {
  // Level l cell (r, c) is set if any base cell of the 2^l x 2^l block starting at
  // (r << l, c << l) holds a line: an OR pooling, so thin lines survive at coarse levels.
  cv::Mat previous = line_mask;
  for (double cell = 2.0 * resolution_m_; cell <= kCoarsestLineCellM * 1.0001; cell *= 2.0) {
    if (previous.rows < 2 || previous.cols < 2) break;
    cv::Mat next((previous.rows + 1) / 2, (previous.cols + 1) / 2, CV_8UC1);
    for (int r = 0; r < next.rows; ++r) {
      const std::uint8_t* top = previous.ptr<std::uint8_t>(2 * r);
      const std::uint8_t* bottom =
          previous.ptr<std::uint8_t>(std::min(2 * r + 1, previous.rows - 1));
      std::uint8_t* out = next.ptr<std::uint8_t>(r);
      const int last = previous.cols - 1;
      for (int c = 0; c < next.cols; ++c) {
        const int c1 = std::min(2 * c + 1, last);
        out[c] = top[2 * c] | top[c1] | bottom[2 * c] | bottom[c1];
      }
    }
    levels_.push_back(next);
    previous = next;
  }
}

void SceneCache::index_boxes(double cell_m) {
  box_cell_m_ = cell_m;
  Bounds bounds;
  std::vector<std::pair<Eigen::Vector2d, Eigen::Vector2d>> extents;
  extents.reserve(boxes_.size());
  for (const Box& box : boxes_) {
    Bounds b;
    for (const Eigen::Vector2d& p : footprint(box)) b.add(p);
    bounds.add(b.min);
    bounds.add(b.max);
    extents.emplace_back(b.min, b.max);
  }
  if (bounds.empty()) {
    box_grid_cols_ = box_grid_rows_ = 0;
    return;
  }
  box_grid_min_ = bounds.min;
  box_grid_cols_ =
      std::max(1, static_cast<int>(std::ceil((bounds.max.x() - bounds.min.x()) / cell_m)));
  box_grid_rows_ =
      std::max(1, static_cast<int>(std::ceil((bounds.max.y() - bounds.min.y()) / cell_m)));
  box_grid_.assign(static_cast<std::size_t>(box_grid_cols_) * box_grid_rows_, {});
  for (std::size_t i = 0; i < boxes_.size(); ++i) {
    const auto [c0, r0] = cell_of(extents[i].first);
    const auto [c1, r1] = cell_of(extents[i].second);
    for (int r = r0; r <= r1; ++r)
      for (int c = c0; c <= c1; ++c)
        box_grid_[static_cast<std::size_t>(r) * box_grid_cols_ + c].push_back(static_cast<int>(i));
  }
}

std::pair<int, int> SceneCache::cell_of(const Eigen::Vector2d& p) const {
  const int c = static_cast<int>(std::floor((p.x() - box_grid_min_.x()) / box_cell_m_));
  const int r = static_cast<int>(std::floor((p.y() - box_grid_min_.y()) / box_cell_m_));
  return {std::clamp(c, 0, box_grid_cols_ - 1), std::clamp(r, 0, box_grid_rows_ - 1)};
}

void SceneCache::boxes_in(const Eigen::Vector2d& min, const Eigen::Vector2d& max,
                          std::vector<int>& out) const {
  if (box_grid_cols_ == 0) return;
  // Outside the grid entirely: nothing there.
  const Eigen::Vector2d grid_max =
      box_grid_min_ + box_cell_m_ * Eigen::Vector2d(box_grid_cols_, box_grid_rows_);
  if (max.x() < box_grid_min_.x() || max.y() < box_grid_min_.y() || min.x() > grid_max.x() ||
      min.y() > grid_max.y())
    return;
  const std::size_t start = out.size();
  const auto [c0, r0] = cell_of(min);
  const auto [c1, r1] = cell_of(max);
  for (int r = r0; r <= r1; ++r)
    for (int c = c0; c <= c1; ++c) {
      const auto& cell = box_grid_[static_cast<std::size_t>(r) * box_grid_cols_ + c];
      out.insert(out.end(), cell.begin(), cell.end());
    }
  std::sort(out.begin() + start, out.end());
  out.erase(std::unique(out.begin() + start, out.end()), out.end());
}

SemanticClass SceneCache::ground_at(double x_m, double y_m) const {
  const double col = (x_m - origin_.x()) / resolution_m_;
  const double row = (origin_.y() - y_m) / resolution_m_;
  const cv::Mat& map = levels_[0];
  if (!(col >= 0.0 && row >= 0.0 && col < map.cols && row < map.rows)) return ground_class_;
  return static_cast<SemanticClass>(
      map.at<std::uint8_t>(static_cast<int>(row), static_cast<int>(col)));
}

int SceneCache::line_level_for(double footprint_m) const {
  // The smallest cell at least as wide as the footprint: neighbouring pixels sample the ground
  // one footprint apart, so a line's run of marked cells is at least that wide and no sample
  // row can step over it. Lines therefore show one to two pixels wide at any distance.
  if (!(footprint_m > resolution_m_)) return 0;
  const int level = static_cast<int>(std::ceil(std::log2(footprint_m / resolution_m_) - 1e-9));
  return std::clamp(level, 0, num_levels() - 1);
}

SemanticClass SceneCache::ground_seen(double x_m, double y_m, double footprint_m) const {
  const int level = line_level_for(footprint_m);
  if (level > 0) {
    const double col = (x_m - origin_.x()) / resolution_m_;
    const double row = (origin_.y() - y_m) / resolution_m_;
    const cv::Mat& map = levels_[0];
    if (col >= 0.0 && row >= 0.0 && col < map.cols && row < map.rows) {
      const int c = static_cast<int>(col) >> level;
      const int r = static_cast<int>(row) >> level;
      if (levels_[level].at<std::uint8_t>(r, c) != 0) return SemanticClass::kRoadLine;
    }
  }
  return ground_at(x_m, y_m);
}

}  // namespace indrive::env
