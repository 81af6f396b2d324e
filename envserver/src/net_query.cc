// RoadNetwork queries and the uniform-grid spatial index behind them.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>

#include "indrive/basics/check.h"
#include "indrive/envserver/net.h"
#include "indrive/envserver/net_geometry.h"

namespace indrive::env {

namespace {
// Grid cell size: a few lane widths, so a cell holds a handful of segments.
constexpr double kCellM = 8.0;
// Cells of the index at most: 32 x 32 km at kCellM, about 0.8 GB of empty cell lists.
constexpr double kMaxIndexCells = 16.0e6;
// Segments are indexed this far beyond their lane surface, the largest margin lanes_at takes.
constexpr double kMaxMarginM = 2.0;
// A point this far beyond a lane's first or last point still counts as on the lane, so the
// seam between a lane and the internal lane that continues it has no gap.
constexpr double kEndToleranceM = 0.05;
// Ties between a normal and an internal lane go to the normal lane by this share of the width.
constexpr double kInternalBias = 0.01;
}  // namespace

struct RoadNetwork::Index {
  struct SegmentRef {
    int lane;
    int segment;
  };
  Eigen::Vector2d origin{0.0, 0.0};
  int nx = 0;
  int ny = 0;
  std::vector<std::vector<SegmentRef>> segments;  // per cell
  std::vector<std::vector<int>> junctions;        // per cell, indices into junctions_

  int cell(const Eigen::Vector2d& p) const {
    const int ix = static_cast<int>(std::floor((p.x() - origin.x()) / kCellM));
    const int iy = static_cast<int>(std::floor((p.y() - origin.y()) / kCellM));
    if (ix < 0 || iy < 0 || ix >= nx || iy >= ny) return -1;
    return iy * nx + ix;
  }
  // Calls fn(cell) for every cell overlapping the box [lo, hi].
  template <typename Fn>
  void for_cells(const Eigen::Vector2d& lo, const Eigen::Vector2d& hi, Fn fn) const {
    const int x0 =
        std::clamp(static_cast<int>(std::floor((lo.x() - origin.x()) / kCellM)), 0, nx - 1);
    const int x1 =
        std::clamp(static_cast<int>(std::floor((hi.x() - origin.x()) / kCellM)), 0, nx - 1);
    const int y0 =
        std::clamp(static_cast<int>(std::floor((lo.y() - origin.y()) / kCellM)), 0, ny - 1);
    const int y1 =
        std::clamp(static_cast<int>(std::floor((hi.y() - origin.y()) / kCellM)), 0, ny - 1);
    for (int iy = y0; iy <= y1; ++iy) {
      for (int ix = x0; ix <= x1; ++ix) fn(iy * nx + ix);
    }
  }
};

RoadNetwork::RoadNetwork() = default;
RoadNetwork::RoadNetwork(RoadNetwork&&) noexcept = default;
RoadNetwork& RoadNetwork::operator=(RoadNetwork&&) noexcept = default;
RoadNetwork::~RoadNetwork() = default;

void RoadNetwork::build_index() {
  // Bounding box of everything drivable.
  Eigen::Vector2d lo = Eigen::Vector2d::Constant(std::numeric_limits<double>::infinity());
  Eigen::Vector2d hi = -lo;
  for (const Lane& lane : lanes_) {
    for (const auto& p : lane.shape) {
      lo = lo.cwiseMin(p - Eigen::Vector2d::Constant(0.5 * lane.width_m));
      hi = hi.cwiseMax(p + Eigen::Vector2d::Constant(0.5 * lane.width_m));
    }
  }
  for (const Junction& junction : junctions_) {
    for (const auto& p : junction.shape) {
      lo = lo.cwiseMin(p);
      hi = hi.cwiseMax(p);
    }
  }
  if (lanes_.empty() && junctions_.empty()) lo = hi = Eigen::Vector2d::Zero();
  // The index is a dense grid of kCellM cells: coordinates from a damaged or foreign file
  // (found by tests/fuzz, target net: 1e28 m overflowed the cell count) must not size it.
  if (!lo.allFinite() || !hi.allFinite()) {
    throw MapError("the network has coordinates that are not finite numbers");
  }
  // Cells along each side (plus one, so that a thin but long network counts too).
  const double cells_x = (hi.x() - lo.x()) / kCellM + 1, cells_y = (hi.y() - lo.y()) / kCellM + 1;
  if (cells_x * cells_y > kMaxIndexCells) {
    char extent[96];
    std::snprintf(extent, sizeof extent, "%.3g x %.3g m", hi.x() - lo.x(), hi.y() - lo.y());
    throw MapError(std::string("the network spans ") + extent +
                   "; at most about 32 x 32 km fit the spatial index: crop the map (netconvert "
                   "--keep-edges.in-boundary)");
  }
  min_corner_ = lo;
  max_corner_ = hi;

  index_ = std::make_unique<Index>();
  Index& index = *index_;
  const double pad = kMaxMarginM + kCellM;
  index.origin = lo - Eigen::Vector2d::Constant(pad);
  index.nx = static_cast<int>(std::ceil((hi.x() - lo.x() + 2 * pad) / kCellM)) + 1;
  index.ny = static_cast<int>(std::ceil((hi.y() - lo.y() + 2 * pad) / kCellM)) + 1;
  index.segments.assign(static_cast<size_t>(index.nx) * index.ny, {});
  index.junctions.assign(index.segments.size(), {});

  for (int l = 0; l < static_cast<int>(lanes_.size()); ++l) {
    const Lane& lane = lanes_[l];
    const double reach = 0.5 * lane.width_m + kMaxMarginM + kEndToleranceM;
    for (int s = 0; s + 1 < static_cast<int>(lane.shape.size()); ++s) {
      const Eigen::Vector2d a = lane.shape[s].cwiseMin(lane.shape[s + 1]);
      const Eigen::Vector2d b = lane.shape[s].cwiseMax(lane.shape[s + 1]);
      index.for_cells(a - Eigen::Vector2d::Constant(reach), b + Eigen::Vector2d::Constant(reach),
                      [&](int cell) {
                        index.segments[cell].push_back({l, s});
                      });
    }
  }
  for (int j = 0; j < static_cast<int>(junctions_.size()); ++j) {
    const auto& shape = junctions_[j].shape;
    if (shape.size() < 3) continue;
    Eigen::Vector2d a = shape[0];
    Eigen::Vector2d b = shape[0];
    for (const auto& p : shape) {
      a = a.cwiseMin(p);
      b = b.cwiseMax(p);
    }
    index.for_cells(a, b, [&](int cell) { index.junctions[cell].push_back(j); });
  }
}

const Lane& RoadNetwork::lane(int index) const {
  INDRIVE_CHECK(index >= 0 && index < static_cast<int>(lanes_.size())) << "lane index " << index;
  return lanes_[index];
}

const Edge& RoadNetwork::edge(int index) const {
  INDRIVE_CHECK(index >= 0 && index < static_cast<int>(edges_.size())) << "edge index " << index;
  return edges_[index];
}

int RoadNetwork::find_lane(std::string_view id) const {
  auto it = lane_by_id_.find(std::string(id));
  return it == lane_by_id_.end() ? -1 : it->second;
}

int RoadNetwork::find_edge(std::string_view id) const {
  auto it = edge_by_id_.find(std::string(id));
  return it == edge_by_id_.end() ? -1 : it->second;
}

const std::vector<int>& RoadNetwork::connections_from(int lane_index) const {
  lane(lane_index);  // range check
  return connections_from_[lane_index];
}

int RoadNetwork::internal_successor(int lane_index) const {
  lane(lane_index);
  return internal_successor_[lane_index];
}

std::vector<int> RoadNetwork::crossing_lanes(const Connection& connection) const {
  std::vector<int> chain;
  int current = connection.via_lane;
  // The chain ends on the connection's target; the bound guards against a malformed cycle.
  while (current >= 0 && current != connection.to_lane && chain.size() < 16) {
    if (!lanes_[current].internal) break;
    chain.push_back(current);
    current = internal_successor_[current];
  }
  return chain;
}

Pose2 RoadNetwork::lane_pose(int lane_index, double s_m) const {
  const Lane& l = lane(lane_index);
  double heading = 0.0;
  const Eigen::Vector2d p = geometry::point_at(l.shape, l.arc_m, s_m, &heading);
  return Pose2{p.x(), p.y(), heading};
}

LanePosition RoadNetwork::project(int lane_index, const Eigen::Vector2d& point) const {
  const Lane& l = lane(lane_index);
  const geometry::PolylineHit hit = geometry::project_polyline(l.shape, l.arc_m, point);
  const Eigen::Vector2d d = l.shape[hit.segment + 1] - l.shape[hit.segment];
  return LanePosition{lane_index, hit.s_m, hit.lateral_m, std::atan2(d.y(), d.x())};
}

std::vector<LanePosition> RoadNetwork::lanes_at(const Eigen::Vector2d& point,
                                                double margin_m) const {
  INDRIVE_CHECK(margin_m >= 0.0 && margin_m <= kMaxMarginM)
      << "margin " << margin_m << " outside [0, " << kMaxMarginM << "]";
  std::vector<LanePosition> found;
  const int cell = index_->cell(point);
  if (cell < 0) return found;
  // Best hit per lane among the segments indexed in this cell.
  struct Best {
    int lane;
    geometry::PolylineHit hit;
  };
  std::vector<Best> best;
  for (const auto& ref : index_->segments[cell]) {
    const Lane& l = lanes_[ref.lane];
    geometry::PolylineHit hit = geometry::project_segment(l.shape, l.arc_m, ref.segment, point);
    auto it =
        std::find_if(best.begin(), best.end(), [&](const Best& b) { return b.lane == ref.lane; });
    if (it == best.end()) {
      best.push_back({ref.lane, hit});
    } else if (hit.distance_m < it->hit.distance_m) {
      it->hit = hit;
    }
  }
  for (const Best& b : best) {
    const Lane& l = lanes_[b.lane];
    if (b.hit.overshoot_m > kEndToleranceM) continue;
    if (std::abs(b.hit.lateral_m) > 0.5 * l.width_m + margin_m) continue;
    const Eigen::Vector2d d = l.shape[b.hit.segment + 1] - l.shape[b.hit.segment];
    found.push_back(LanePosition{b.lane, b.hit.s_m, b.hit.lateral_m, std::atan2(d.y(), d.x())});
  }
  std::sort(found.begin(), found.end(),
            [](const LanePosition& a, const LanePosition& b) { return a.lane < b.lane; });
  return found;
}

namespace {
// A lane more than this off the vehicle's heading crosses its path rather than carries it.
constexpr double kCrossingRad = M_PI / 3.0;

double fit_score(const Lane& lane, const LanePosition& at) {
  return std::abs(at.lateral_m) / lane.width_m + (lane.internal ? kInternalBias : 0.0);
}
}  // namespace

std::optional<LanePosition> RoadNetwork::locate(const Eigen::Vector2d& point) const {
  std::optional<LanePosition> best;
  double best_score = std::numeric_limits<double>::infinity();
  for (const LanePosition& at : lanes_at(point)) {
    const double score = fit_score(lanes_[at.lane], at);
    if (score < best_score) {
      best_score = score;
      best = at;
    }
  }
  return best;
}

std::optional<LanePosition> RoadNetwork::locate(const Eigen::Vector2d& point,
                                                double yaw_rad) const {
  std::optional<LanePosition> best;
  double best_score = std::numeric_limits<double>::infinity();
  for (const LanePosition& at : lanes_at(point)) {
    // Lanes against the vehicle's direction only win when nothing else is there, and lanes
    // that cross its direction (more than 60 degrees off) only over those: where two roads
    // cross without a junction (a bridge over a road, as on CARLA's Town04, converted flat),
    // the road under the vehicle is the one it drives along, however near the other's centre.
    const double off = std::abs(wrap_angle(yaw_rad - at.heading_rad));
    const double tier = off > 0.5 * M_PI ? 10.0 : off > kCrossingRad ? 5.0 : 0.0;
    const double score = fit_score(lanes_[at.lane], at) + tier;
    if (score < best_score) {
      best_score = score;
      best = at;
    }
  }
  return best;
}

bool RoadNetwork::in_junction(const Eigen::Vector2d& point) const {
  const int cell = index_->cell(point);
  if (cell < 0) return false;
  for (int j : index_->junctions[cell]) {
    if (geometry::point_in_polygon(junctions_[j].shape, point)) return true;
  }
  return false;
}

bool RoadNetwork::is_drivable(const Eigen::Vector2d& point) const {
  if (in_junction(point)) return true;
  return !lanes_at(point).empty();
}

}  // namespace indrive::env
