// Small planar geometry of the road network (polylines, arc lengths, closest points), used by
// the net, routes and scene code and tested on its own (tests/envserver/net_town_test.cc).
#pragma once

#include <Eigen/Core>
#include <vector>

namespace indrive::env::geometry {

// Closest point of a polyline to a point.
struct PolylineHit {
  int segment = 0;         // index of the segment holding the closest point
  double s_m = 0.0;        // arc length of the closest point
  double lateral_m = 0.0;  // signed distance, positive to the left of the direction of travel
  double distance_m = 0.0;
  double overshoot_m = 0.0;  // how far before the start / past the end the point lies (>= 0)
  Eigen::Vector2d closest{0.0, 0.0};
};

// Cumulative arc length at each point; arc[0] = 0. points has at least 1 entry.
std::vector<double> arc_lengths(const std::vector<Eigen::Vector2d>& points);

// Projects `point` onto segment `segment` of the polyline (points, arc as from arc_lengths).
PolylineHit project_segment(const std::vector<Eigen::Vector2d>& points,
                            const std::vector<double>& arc, int segment,
                            const Eigen::Vector2d& point);

// Projects `point` onto the whole polyline (the closest of all segments).
PolylineHit project_polyline(const std::vector<Eigen::Vector2d>& points,
                             const std::vector<double>& arc, const Eigen::Vector2d& point);

// Point and direction (radians) at arc length s (clamped to the polyline).
Eigen::Vector2d point_at(const std::vector<Eigen::Vector2d>& points, const std::vector<double>& arc,
                         double s, double* heading_rad);

// Crossing-number test; the polygon is closed implicitly.
bool point_in_polygon(const std::vector<Eigen::Vector2d>& polygon, const Eigen::Vector2d& point);

// Signed area (positive when counter-clockwise).
double signed_area(const std::vector<Eigen::Vector2d>& polygon);

// Offsets a polyline sideways by `offset_m` (positive to the left), mitering the joints.
std::vector<Eigen::Vector2d> offset_polyline(const std::vector<Eigen::Vector2d>& points,
                                             double offset_m);

// Removes consecutive points closer than `tolerance_m`.
std::vector<Eigen::Vector2d> dedupe(const std::vector<Eigen::Vector2d>& points,
                                    double tolerance_m = 1e-6);

// Distance from a point to a segment.
double segment_distance(const Eigen::Vector2d& a, const Eigen::Vector2d& b,
                        const Eigen::Vector2d& point);

}  // namespace indrive::env::geometry
