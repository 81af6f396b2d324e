#include "indrive/envserver/net_geometry.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "indrive/basics/check.h"

namespace indrive::env::geometry {

std::vector<double> arc_lengths(const std::vector<Eigen::Vector2d>& points) {
  std::vector<double> arc(points.size(), 0.0);
  for (size_t i = 1; i < points.size(); ++i)
    arc[i] = arc[i - 1] + (points[i] - points[i - 1]).norm();
  return arc;
}

PolylineHit project_segment(const std::vector<Eigen::Vector2d>& points,
                            const std::vector<double>& arc, int segment,
                            const Eigen::Vector2d& point) {
  const Eigen::Vector2d& a = points[segment];
  const Eigen::Vector2d& b = points[segment + 1];
  const Eigen::Vector2d ab = b - a;
  const double length = arc[segment + 1] - arc[segment];
  PolylineHit hit;
  hit.segment = segment;
  double t = length > 0.0 ? (point - a).dot(ab) / (length * length) : 0.0;
  // Only the polyline's own ends can be overshot; inner joints are covered by the neighbours.
  if (segment == 0 && t < 0.0) hit.overshoot_m = -t * length;
  if (segment + 2 == static_cast<int>(points.size()) && t > 1.0)
    hit.overshoot_m = (t - 1.0) * length;
  t = std::clamp(t, 0.0, 1.0);
  hit.closest = a + t * ab;
  hit.s_m = arc[segment] + t * length;
  const Eigen::Vector2d d = point - hit.closest;
  hit.distance_m = d.norm();
  const double cross = length > 0.0 ? (ab.x() * d.y() - ab.y() * d.x()) / length : 0.0;
  // The perpendicular component carries the side; at a joint the full distance counts.
  hit.lateral_m = cross >= 0.0 ? hit.distance_m : -hit.distance_m;
  if (hit.overshoot_m > 0.0) hit.lateral_m = cross;
  return hit;
}

PolylineHit project_polyline(const std::vector<Eigen::Vector2d>& points,
                             const std::vector<double>& arc, const Eigen::Vector2d& point) {
  INDRIVE_CHECK(points.size() >= 2) << "polyline needs two points";
  PolylineHit best;
  best.distance_m = std::numeric_limits<double>::infinity();
  for (int i = 0; i + 1 < static_cast<int>(points.size()); ++i) {
    PolylineHit hit = project_segment(points, arc, i, point);
    if (hit.distance_m < best.distance_m) best = hit;
  }
  return best;
}

Eigen::Vector2d point_at(const std::vector<Eigen::Vector2d>& points, const std::vector<double>& arc,
                         double s, double* heading_rad) {
  INDRIVE_CHECK(points.size() >= 2) << "polyline needs two points";
  s = std::clamp(s, 0.0, arc.back());
  auto it = std::upper_bound(arc.begin(), arc.end(), s);
  int segment = static_cast<int>(it - arc.begin()) - 1;
  segment = std::clamp(segment, 0, static_cast<int>(points.size()) - 2);
  const Eigen::Vector2d ab = points[segment + 1] - points[segment];
  const double length = arc[segment + 1] - arc[segment];
  const double t = length > 0.0 ? (s - arc[segment]) / length : 0.0;
  if (heading_rad != nullptr) *heading_rad = std::atan2(ab.y(), ab.x());
  return points[segment] + t * ab;
}

bool point_in_polygon(const std::vector<Eigen::Vector2d>& polygon, const Eigen::Vector2d& point) {
  bool inside = false;
  const size_t n = polygon.size();
  for (size_t i = 0, j = n - 1; i < n; j = i++) {
    const Eigen::Vector2d& a = polygon[i];
    const Eigen::Vector2d& b = polygon[j];
    if ((a.y() > point.y()) != (b.y() > point.y())) {
      const double x = a.x() + (point.y() - a.y()) * (b.x() - a.x()) / (b.y() - a.y());
      if (point.x() < x) inside = !inside;
    }
  }
  return inside;
}

double signed_area(const std::vector<Eigen::Vector2d>& polygon) {
  double twice = 0.0;
  const size_t n = polygon.size();
  for (size_t i = 0, j = n - 1; i < n; j = i++) {
    twice += polygon[j].x() * polygon[i].y() - polygon[i].x() * polygon[j].y();
  }
  return 0.5 * twice;
}

std::vector<Eigen::Vector2d> offset_polyline(const std::vector<Eigen::Vector2d>& points,
                                             double offset_m) {
  const size_t n = points.size();
  std::vector<Eigen::Vector2d> out;
  if (n < 2) return points;
  out.reserve(n);
  auto normal = [&](size_t i) {
    Eigen::Vector2d d = (points[i + 1] - points[i]).normalized();
    return Eigen::Vector2d(-d.y(), d.x());
  };
  for (size_t i = 0; i < n; ++i) {
    if (i == 0) {
      out.push_back(points[0] + offset_m * normal(0));
    } else if (i + 1 == n) {
      out.push_back(points[i] + offset_m * normal(i - 1));
    } else {
      const Eigen::Vector2d n0 = normal(i - 1);
      const Eigen::Vector2d n1 = normal(i);
      Eigen::Vector2d bisector = n0 + n1;
      const double norm = bisector.norm();
      // A near-reversal has no usable miter: fall back to the incoming normal.
      if (norm < 1e-6) {
        out.push_back(points[i] + offset_m * n0);
        continue;
      }
      bisector /= norm;
      const double cos_half = std::max(bisector.dot(n0), 0.3);  // limits miter spikes
      out.push_back(points[i] + (offset_m / cos_half) * bisector);
    }
  }
  return out;
}

std::vector<Eigen::Vector2d> dedupe(const std::vector<Eigen::Vector2d>& points,
                                    double tolerance_m) {
  std::vector<Eigen::Vector2d> out;
  out.reserve(points.size());
  for (const auto& p : points) {
    if (out.empty() || (p - out.back()).norm() > tolerance_m) out.push_back(p);
  }
  return out;
}

double segment_distance(const Eigen::Vector2d& a, const Eigen::Vector2d& b,
                        const Eigen::Vector2d& point) {
  const Eigen::Vector2d ab = b - a;
  const double len2 = ab.squaredNorm();
  const double t = len2 > 0.0 ? std::clamp((point - a).dot(ab) / len2, 0.0, 1.0) : 0.0;
  return (point - (a + t * ab)).norm();
}

}  // namespace indrive::env::geometry
