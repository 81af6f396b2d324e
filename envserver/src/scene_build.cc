// Static scene from a road network: ground polygons, painted lines, buildings and vegetation.
#include "indrive/envserver/scene_build.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <set>

#include "indrive/basics/check.h"
#include "indrive/envserver/net_geometry.h"

namespace indrive::env {

namespace {

using Points = std::vector<Eigen::Vector2d>;

// A strip between two parallel polylines, as one polygon (left side forward, right side back).
Points strip(const Points& centre, double left_m, double right_m) {
  Points polygon = geometry::offset_polyline(centre, left_m);
  Points other = geometry::offset_polyline(centre, right_m);
  polygon.insert(polygon.end(), other.rbegin(), other.rend());
  return polygon;
}

// Convex hull (monotone chain), counter-clockwise.
Points convex_hull(Points points) {
  std::sort(points.begin(), points.end(), [](const auto& a, const auto& b) {
    return a.x() < b.x() || (a.x() == b.x() && a.y() < b.y());
  });
  if (points.size() < 3) return points;
  auto cross = [](const Eigen::Vector2d& o, const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
    return (a.x() - o.x()) * (b.y() - o.y()) - (a.y() - o.y()) * (b.x() - o.x());
  };
  Points hull(2 * points.size());
  size_t k = 0;
  for (size_t i = 0; i < points.size(); ++i) {
    while (k >= 2 && cross(hull[k - 2], hull[k - 1], points[i]) <= 0) --k;
    hull[k++] = points[i];
  }
  for (size_t i = points.size() - 1, t = k + 1; i > 0; --i) {
    while (k >= t && cross(hull[k - 2], hull[k - 1], points[i - 1]) <= 0) --k;
    hull[k++] = points[i - 1];
  }
  hull.resize(k - 1);
  return hull;
}

// Uniform number in [0, 1) from the generator's raw output (the standard distributions are not
// identical across library versions, and scenes must be).
double uniform(std::mt19937& rng) { return static_cast<double>(rng()) / 4294967296.0; }

// Index of the edge driving the other way between the same junctions, or -1.
std::vector<int> opposite_edges(const RoadNetwork& net) {
  std::vector<int> opposite(net.edges().size(), -1);
  for (size_t a = 0; a < net.edges().size(); ++a) {
    const Edge& ea = net.edges()[a];
    if (ea.internal) continue;
    for (size_t b = 0; b < net.edges().size(); ++b) {
      const Edge& eb = net.edges()[b];
      if (a != b && !eb.internal && eb.from_junction == ea.to_junction &&
          eb.to_junction == ea.from_junction) {
        opposite[a] = static_cast<int>(b);
        break;
      }
    }
  }
  return opposite;
}

// Distance from a point to the nearest road surface (0 on the road).
class RoadDistance {
 public:
  explicit RoadDistance(const RoadNetwork& net) : net_(net) {}
  double operator()(const Eigen::Vector2d& p) const {
    double best = std::numeric_limits<double>::infinity();
    for (const Lane& lane : net_.lanes()) {
      for (size_t i = 0; i + 1 < lane.shape.size(); ++i) {
        best = std::min(best, geometry::segment_distance(lane.shape[i], lane.shape[i + 1], p) -
                                  0.5 * lane.width_m);
      }
    }
    for (const Junction& junction : net_.junctions()) {
      const auto& shape = junction.shape;
      if (shape.size() < 3) continue;
      if (geometry::point_in_polygon(shape, p)) return 0.0;
      for (size_t i = 0, j = shape.size() - 1; i < shape.size(); j = i++) {
        best = std::min(best, geometry::segment_distance(shape[j], shape[i], p));
      }
    }
    return std::max(best, 0.0);
  }

 private:
  const RoadNetwork& net_;
};

}  // namespace

StaticScene build_static_scene(const RoadNetwork& net, const SceneOptions& options) {
  INDRIVE_CHECK(options.sidewalk_width_m >= 0.0 && options.building_cell_m > 2.0)
      << "bad scene options";
  StaticScene scene;
  scene.ground_class = SemanticClass::kVegetation;
  const std::vector<int> opposite = opposite_edges(net);

  // Sidewalks first: strips along the outer sides of every road, and a widened hull around
  // every junction that fills the corners. The road surfaces drawn next cover the overlaps.
  const double sidewalk = options.sidewalk_width_m;
  for (size_t e = 0; e < net.edges().size() && sidewalk > 0.0; ++e) {
    const Edge& edge = net.edges()[e];
    if (edge.internal || edge.lanes.empty()) continue;
    const Lane& right = net.lane(edge.lanes.front());
    scene.ground.push_back({SemanticClass::kSidewalk, strip(right.shape, -0.5 * right.width_m,
                                                            -0.5 * right.width_m - sidewalk)});
    if (opposite[e] < 0) {
      const Lane& left = net.lane(edge.lanes.back());
      scene.ground.push_back(
          {SemanticClass::kSidewalk,
           strip(left.shape, 0.5 * left.width_m + sidewalk, 0.5 * left.width_m)});
    }
  }
  for (const Junction& junction : net.junctions()) {
    if (junction.shape.size() < 3 || sidewalk <= 0.0) continue;
    Points ring;
    for (const auto& p : junction.shape) {
      for (int k = 0; k < 16; ++k) {
        const double angle = 2.0 * M_PI * k / 16.0;
        ring.push_back(p + sidewalk * Eigen::Vector2d(std::cos(angle), std::sin(angle)));
      }
    }
    scene.ground.push_back({SemanticClass::kSidewalk, convex_hull(ring)});
  }

  // Road surfaces: junction areas, then every lane (internal lanes fill the junction corners
  // that the junction outline cuts).
  for (const Junction& junction : net.junctions()) {
    if (junction.shape.size() >= 3 && std::abs(geometry::signed_area(junction.shape)) > 1.0) {
      scene.ground.push_back({SemanticClass::kRoad, junction.shape});
    }
  }
  for (const Lane& lane : net.lanes()) {
    scene.ground.push_back(
        {SemanticClass::kRoad, strip(lane.shape, 0.5 * lane.width_m, -0.5 * lane.width_m)});
  }

  // Painted lines along normal edges: the centre line once per pair of opposite edges, dashed
  // lines between lanes of one direction, and edge lines just inside the road border.
  const double inset = 0.3;  // edge lines sit this far inside the road border
  for (size_t e = 0; e < net.edges().size(); ++e) {
    const Edge& edge = net.edges()[e];
    if (edge.internal || edge.lanes.empty()) continue;
    const Lane& right = net.lane(edge.lanes.front());
    const Lane& left = net.lane(edge.lanes.back());
    if (opposite[e] < 0 || static_cast<int>(e) < opposite[e]) {
      // For a one-way edge this is its left edge line instead of a centre line.
      const double offset = opposite[e] < 0 ? 0.5 * left.width_m - inset : 0.5 * left.width_m;
      scene.lines.push_back({geometry::offset_polyline(left.shape, offset), options.line_width_m,
                             opposite[e] >= 0 && options.centre_line_dashed});
    }
    for (size_t k = 0; k + 1 < edge.lanes.size(); ++k) {
      const Lane& lane = net.lane(edge.lanes[k]);
      scene.lines.push_back(
          {geometry::offset_polyline(lane.shape, 0.5 * lane.width_m), options.line_width_m, true});
    }
    scene.lines.push_back({geometry::offset_polyline(right.shape, -0.5 * right.width_m + inset),
                           options.line_width_m, false});
  }

  // Boxes on a grid beyond the sidewalks: each cell takes the largest square footprint that
  // keeps the setback from every road. A second pass with half-size cells fills the strips
  // the coarse grid leaves along the sidewalks, so blocks are lined with buildings.
  const RoadDistance road_distance(net);
  const double clearance = sidewalk + options.building_setback_m;
  const Eigen::Vector2d lo = net.min_corner() - Eigen::Vector2d::Constant(options.margin_m);
  const Eigen::Vector2d hi = net.max_corner() + Eigen::Vector2d::Constant(options.margin_m);
  std::mt19937 rng(options.seed);
  // Axis-aligned squares already placed, to keep the fine pass out of them.
  auto overlaps = [&](const Eigen::Vector2d& centre, double half) {
    for (const Box& box : scene.boxes) {
      const double other = 0.5 * box.length_m + 0.5;  // keeps a narrow alley between boxes
      if (std::abs(box.pose.x_m - centre.x()) < half + other &&
          std::abs(box.pose.y_m - centre.y()) < half + other) {
        return true;
      }
    }
    return false;
  };
  for (const double cell : {options.building_cell_m, 0.5 * options.building_cell_m}) {
    const double min_half = std::min(3.0, 0.5 * cell - 0.5);
    for (double y = lo.y() + 0.5 * cell; y < hi.y(); y += cell) {
      for (double x = lo.x() + 0.5 * cell; x < hi.x(); x += cell) {
        const Eigen::Vector2d centre(x, y);
        const double vegetation_draw = uniform(rng);
        const double height_draw = uniform(rng);
        if (road_distance(centre) < clearance + min_half) continue;
        double half = 0.5 * cell - 0.5;
        for (; half >= min_half; half -= 1.0) {
          // Corners and edge midpoints: a road is a straight line at this scale, so the
          // footprint's closest point to it is one of these.
          static constexpr int kSamples[8][2] = {{-1, -1}, {0, -1}, {1, -1}, {-1, 0},
                                                 {1, 0},   {-1, 1}, {0, 1},  {1, 1}};
          bool fits = true;
          for (const auto& sample : kSamples) {
            const Eigen::Vector2d point = centre + half * Eigen::Vector2d(sample[0], sample[1]);
            if (road_distance(point) < clearance) {
              fits = false;
              break;
            }
          }
          if (fits) break;
        }
        if (half < min_half || overlaps(centre, half)) continue;
        Box box;
        box.pose = Pose2{x, y, 0.0};
        if (vegetation_draw < options.vegetation_fraction) {
          // Vegetation: a lower, slightly smaller clump.
          box.cls = SemanticClass::kVegetation;
          box.length_m = box.width_m = 2.0 * half - 1.0;
          box.height_m = 4.0 + 5.0 * height_draw;
        } else {
          box.cls = SemanticClass::kBuilding;
          box.length_m = box.width_m = 2.0 * half;
          box.height_m = 6.0 + 20.0 * height_draw;
        }
        scene.boxes.push_back(box);
      }
    }
  }

  scene.min_corner = lo;
  scene.max_corner = hi;
  return scene;
}

std::vector<SpawnPoint> spawn_points(const RoadNetwork& net, double spacing_m,
                                     double junction_clearance_m) {
  INDRIVE_CHECK(spacing_m > 0.0) << "spawn spacing must be positive";
  std::vector<SpawnPoint> spawns;
  for (int l = 0; l < static_cast<int>(net.lanes().size()); ++l) {
    const Lane& lane = net.lane(l);
    if (lane.internal) continue;
    for (double s = junction_clearance_m; s <= lane.length_m - junction_clearance_m;
         s += spacing_m) {
      spawns.push_back(SpawnPoint{net.lane_pose(l, s), l, lane.id, s});
    }
  }
  return spawns;
}

}  // namespace indrive::env
