// Route construction from a spec, projection onto the route, and the progress tracker.
#include <algorithm>
#include <cmath>
#include <limits>

#include "indrive/basics/check.h"
#include "indrive/envserver/net_geometry.h"
#include "indrive/envserver/routes.h"

namespace indrive::env {

namespace {

// Picks the connection from edge `from` to edge `to`, preferring one that starts on
// `preferred_lane` (continuing the lane the route is on), then the rightmost lane.
const Connection* find_connection(const RoadNetwork& net, int from, int to, int preferred_lane) {
  const Connection* best = nullptr;
  for (int lane : net.edge(from).lanes) {
    for (int c : net.connections_from(lane)) {
      const Connection& connection = net.connections()[c];
      if (net.lane(connection.to_lane).edge != to) continue;
      if (connection.direction == TurnDirection::kTurnaround && from != to) continue;
      if (best == nullptr) best = &connection;
      if (connection.from_lane == preferred_lane && best->from_lane != preferred_lane) {
        best = &connection;
      }
    }
  }
  return best;
}

}  // namespace

Route::Route(const RoadNetwork& net, const RouteSpec& spec, double spacing_m) : spec_(spec) {
  INDRIVE_CHECK(spacing_m > 0.0) << "waypoint spacing must be positive";
  // A route given by its end points: the edges are the shortest path between them.
  std::optional<PointPath> path;
  if (spec.start.has_value() != spec.end.has_value()) {
    throw RouteError("route '" + spec.name + "' gives one end point; give both start and end");
  }
  if (spec.start) {
    if (spec.loop) throw RouteError("route '" + spec.name + "': a loop has no end points");
    const bool carla = spec.frame == PointFrame::kCarla;
    spec_.start = carla ? carla_to_network(net, *spec.start) : *spec.start;
    spec_.end = carla ? carla_to_network(net, *spec.end) : *spec.end;
    // CARLA's yaw turns clockwise seen from above in the network frame.
    if (carla && spec.start_heading_rad) spec_.start_heading_rad = -*spec.start_heading_rad;
    if (carla && spec.end_heading_rad) spec_.end_heading_rad = -*spec.end_heading_rad;
    spec_.frame = PointFrame::kNetwork;
    try {
      path = route_edges_between(net, *spec_.start, *spec_.end, spec_.start_heading_rad,
                                 spec_.end_heading_rad);
    } catch (const RouteError& error) {
      throw RouteError("route '" + spec.name + "': " + error.what());
    }
    if (!spec.edges.empty() && spec.edges != path->edges) {
      throw RouteError("route '" + spec.name +
                       "': its edges are not the shortest path between its end points; leave "
                       "'edges' out to have them found");
    }
    spec_.edges = path->edges;
  }
  if (spec_.edges.empty()) throw RouteError("route '" + spec.name + "' has no edges");
  std::vector<int> edges;
  for (const std::string& id : spec_.edges) {
    const int edge = net.find_edge(id);
    if (edge < 0 || net.edge(edge).internal || net.edge(edge).lanes.empty()) {
      throw RouteError("route '" + spec.name + "': edge '" + id +
                       "' is not a drivable edge of network '" + net.source().string() +
                       "'; fix the route file or derive the routes from the network");
    }
    edges.push_back(edge);
  }
  if (spec_.loop && edges.size() < 2) {
    throw RouteError("route '" + spec.name + "': a loop needs at least two edges");
  }

  // Lane sequence: each edge's lane, then the internal lanes crossing the next junction.
  const size_t hops = spec.loop ? edges.size() : edges.size() - 1;
  int lane = path ? path->start_lane : net.edge(edges[0]).lanes.front();
  std::vector<int> edge_lanes(edges.size(), -1);
  std::vector<const Connection*> connections;
  for (size_t i = 0; i < hops; ++i) {
    const int from = edges[i];
    const int to = edges[(i + 1) % edges.size()];
    const Connection* connection = find_connection(net, from, to, lane);
    if (connection == nullptr) {
      throw RouteError("route '" + spec.name + "': no connection from edge '" + spec_.edges[i] +
                       "' to edge '" + spec_.edges[(i + 1) % edges.size()] +
                       "'; consecutive edges must meet at a junction with a permitted move");
    }
    edge_lanes[i] = connection->from_lane;
    connections.push_back(connection);
    turns_.push_back(connection->direction);
    lane = connection->to_lane;
  }
  if (!spec.loop) edge_lanes.back() = lane;
  for (size_t i = 0; i < edges.size(); ++i) {
    lanes_.push_back(edge_lanes[i]);
    if (i < connections.size()) {
      for (int internal : net.crossing_lanes(*connections[i])) lanes_.push_back(internal);
    }
  }
  if (spec.loop) lanes_.push_back(edge_lanes[0]);  // closes the centre line; dropped below

  // Dense centre line through all lanes; a loop ends where it started.
  for (size_t k = 0; k < lanes_.size(); ++k) {
    const Lane& l = net.lane(lanes_[k]);
    const bool closing = spec.loop && k + 1 == lanes_.size();
    const size_t count = closing ? 1 : l.shape.size();
    for (size_t p = 0; p < count; ++p) {
      if (!line_.empty() && (l.shape[p] - line_.back()).norm() < 1e-3) continue;
      line_.push_back(l.shape[p]);
      line_width_m_.push_back(l.width_m);
      line_lane_.push_back(lanes_[k]);
    }
  }
  if (spec.loop) lanes_.pop_back();
  INDRIVE_CHECK(line_.size() >= 2) << "route '" << spec.name << "' has a degenerate centre line";
  line_s_m_ = geometry::arc_lengths(line_);
  if (path) {
    // From the start point's projection on the first lane to the end point's on the last
    // (the last lane's points are its whole shape, appended last).
    const double last_lane_s = line_s_m_.back() - net.lane(lanes_.back()).length_m;
    const double end_s = edges.size() == 1 ? path->end_s_m : last_lane_s + path->end_s_m;
    trim_line(path->start_s_m, std::clamp(end_s, path->start_s_m, line_s_m_.back()));
  } else if (!spec.loop) {
    // The terminal waypoint is set back from the end of the last edge (its junction's stop
    // line), by kRouteEndSetbackM or half that edge when it is shorter. The last edge's points
    // follow the one it shares with the lane before (kept once, under that lane).
    size_t first = line_.size() - 1;
    while (first > 0 && line_lane_[first - 1] == lanes_.back()) --first;
    const double last_edge_m = line_s_m_.back() - line_s_m_[first > 0 ? first - 1 : 0];
    const double end_s = line_s_m_.back() - std::min(kRouteEndSetbackM, 0.5 * last_edge_m);
    const Eigen::Vector2d end = geometry::point_at(line_, line_s_m_, end_s, nullptr);
    const size_t keep = std::max<size_t>(
        1, std::upper_bound(line_s_m_.begin(), line_s_m_.end(), end_s - 1e-6) - line_s_m_.begin());
    line_.resize(keep);
    line_width_m_.resize(keep);
    line_lane_.resize(keep);
    line_.push_back(end);
    line_width_m_.push_back(line_width_m_.back());
    line_lane_.push_back(line_lane_.back());
    line_s_m_ = geometry::arc_lengths(line_);
  }
  length_m_ = line_s_m_.back();
  destination_ = spec_.end.value_or(spec_.loop ? line_.front() : line_.back());

  // Waypoints evenly spread at about spacing_m; a loop does not repeat its start.
  const int intervals = std::max(1, static_cast<int>(std::lround(length_m_ / spacing_m)));
  const double step = length_m_ / intervals;
  const int count = spec.loop ? intervals : intervals + 1;
  for (int i = 0; i < count; ++i) {
    const double s = std::min(i * step, length_m_);
    double heading = 0.0;
    Waypoint waypoint;
    waypoint.position = geometry::point_at(line_, line_s_m_, s, &heading);
    waypoint.heading_rad = heading;
    waypoint.s_m = s;
    auto it = std::upper_bound(line_s_m_.begin(), line_s_m_.end(), s);
    const size_t segment =
        std::min<size_t>(std::max<ptrdiff_t>(it - line_s_m_.begin() - 1, 0), line_.size() - 2);
    waypoint.lane = line_lane_[segment];
    waypoint.lane_width_m = line_width_m_[segment];
    waypoints_.push_back(waypoint);
  }
}

void Route::trim_line(double from_s, double to_s) {
  std::vector<Eigen::Vector2d> line;
  std::vector<double> width;
  std::vector<int> lane;
  const auto keep = [&](const Eigen::Vector2d& point, size_t segment) {
    if (!line.empty() && (point - line.back()).norm() < 1e-3) return;
    line.push_back(point);
    width.push_back(line_width_m_[segment]);
    lane.push_back(line_lane_[segment]);
  };
  const auto segment_of = [&](double s) {
    const auto it = std::upper_bound(line_s_m_.begin(), line_s_m_.end(), s);
    return std::min<size_t>(std::max<ptrdiff_t>(it - line_s_m_.begin() - 1, 0), line_.size() - 2);
  };
  keep(geometry::point_at(line_, line_s_m_, from_s, nullptr), segment_of(from_s));
  for (size_t i = 0; i < line_.size(); ++i) {
    if (line_s_m_[i] > from_s && line_s_m_[i] < to_s) keep(line_[i], std::min(i, line_.size() - 2));
  }
  keep(geometry::point_at(line_, line_s_m_, to_s, nullptr), segment_of(to_s));
  INDRIVE_CHECK(line.size() >= 2) << "route '" << spec_.name << "' is shorter than 1 mm";
  line_ = std::move(line);
  line_width_m_ = std::move(width);
  line_lane_ = std::move(lane);
  line_s_m_ = geometry::arc_lengths(line_);
}

Pose2 Route::start_pose() const { return pose_at(0.0); }

Pose2 Route::pose_at(double s_m) const {
  if (is_loop()) {
    s_m = std::fmod(s_m, length_m_);
    if (s_m < 0.0) s_m += length_m_;
  }
  double heading = 0.0;
  const Eigen::Vector2d p = geometry::point_at(line_, line_s_m_, s_m, &heading);
  return Pose2{p.x(), p.y(), heading};
}

RoutePoint Route::project(const Eigen::Vector2d& point, double s_hint_m, double window_m) const {
  // Arc-length intervals to search (two when a loop's window wraps past the start).
  std::vector<std::pair<double, double>> windows;
  if (window_m < 0.0 || (is_loop() && 2.0 * window_m >= length_m_)) {
    windows.emplace_back(0.0, length_m_);
  } else if (is_loop()) {
    double lo = std::fmod(s_hint_m - window_m, length_m_);
    if (lo < 0.0) lo += length_m_;
    const double hi = lo + 2.0 * window_m;
    windows.emplace_back(lo, std::min(hi, length_m_));
    if (hi > length_m_) windows.emplace_back(0.0, hi - length_m_);
  } else {
    windows.emplace_back(std::max(0.0, s_hint_m - window_m),
                         std::min(length_m_, s_hint_m + window_m));
  }

  RoutePoint best;
  double best_distance = std::numeric_limits<double>::infinity();
  for (size_t i = 0; i + 1 < line_.size(); ++i) {
    const double s0 = line_s_m_[i];
    const double s1 = line_s_m_[i + 1];
    if (s1 <= s0) continue;
    const Eigen::Vector2d direction = (line_[i + 1] - line_[i]) / (s1 - s0);
    for (const auto& [a, b] : windows) {
      const double lo = std::max(s0, a);
      const double hi = std::min(s1, b);
      if (lo > hi) continue;
      // Closest point of the part of this segment inside the window.
      const double t = std::clamp((point - line_[i]).dot(direction), lo - s0, hi - s0);
      const Eigen::Vector2d closest = line_[i] + t * direction;
      const Eigen::Vector2d offset = point - closest;
      const double distance = offset.norm();
      if (distance < best_distance) {
        best_distance = distance;
        const double cross = direction.x() * offset.y() - direction.y() * offset.x();
        best.s_m = s0 + t;
        best.lateral_m = cross >= 0.0 ? distance : -distance;
        best.heading_rad = std::atan2(direction.y(), direction.x());
        best.lane_width_m = line_width_m_[i];
      }
    }
  }
  if (is_loop() && best.s_m >= length_m_) best.s_m -= length_m_;
  return best;
}

int Route::next_waypoint(double s_m) const {
  if (is_loop()) {
    s_m = std::fmod(s_m, length_m_);
    if (s_m < 0.0) s_m += length_m_;
  }
  auto it = std::upper_bound(waypoints_.begin(), waypoints_.end(), s_m,
                             [](double s, const Waypoint& w) { return s < w.s_m; });
  if (it == waypoints_.end()) return is_loop() ? 0 : static_cast<int>(waypoints_.size()) - 1;
  return static_cast<int>(it - waypoints_.begin());
}

// --- tracker -----------------------------------------------------------------------------------

namespace {
// A vehicle moves well under a metre per 0.1 s step; this window keeps the projection local.
constexpr double kTrackWindowM = 15.0;
}  // namespace

RouteTracker::RouteTracker(const Route& route, double destination_radius_m)
    : route_(&route), destination_radius_m_(destination_radius_m) {
  reset();
}

void RouteTracker::reset(double s_m) {
  start_s_m_ = s_m;
  s_m_ = s_m;
  progress_m_ = 0.0;
  best_progress_m_ = 0.0;
  last_ = RouteStep{};
  last_.next_waypoint = route_->next_waypoint(s_m);
}

namespace {
// Number of waypoints at or behind unwrapped arc length u (laps count on loops).
long waypoints_behind(const Route& route, double u) {
  const auto& waypoints = route.waypoints();
  const long n = static_cast<long>(waypoints.size());
  double within = u;
  long laps = 0;
  if (route.is_loop()) {
    laps = static_cast<long>(std::floor(u / route.length_m()));
    within = u - laps * route.length_m();
  }
  const long count = std::upper_bound(waypoints.begin(), waypoints.end(), within,
                                      [](double s, const Waypoint& w) { return s < w.s_m; }) -
                     waypoints.begin();
  return laps * n + count;
}
}  // namespace

RouteStep RouteTracker::update(const Pose2& pose) {
  const Route& route = *route_;
  const RoutePoint at = route.project({pose.x_m, pose.y_m}, s_m_, kTrackWindowM);
  double delta = at.s_m - s_m_;
  if (route.is_loop()) {
    // The shorter way round is the true motion.
    if (delta > 0.5 * route.length_m()) delta -= route.length_m();
    if (delta < -0.5 * route.length_m()) delta += route.length_m();
  }
  s_m_ = at.s_m;
  progress_m_ += delta;

  RouteStep step;
  step.progress_m = progress_m_;
  step.delta_m = delta;
  if (progress_m_ > best_progress_m_) {
    step.waypoints_passed =
        static_cast<int>(waypoints_behind(route, start_s_m_ + progress_m_) -
                         waypoints_behind(route, start_s_m_ + best_progress_m_));
    best_progress_m_ = progress_m_;
  }
  step.next_waypoint = route.next_waypoint(s_m_);
  step.lateral_m = at.lateral_m;
  step.distance_to_route_m = std::abs(at.lateral_m);
  if (route.is_loop()) {
    step.finished = route.length_m() - progress_m_ <= kLapToleranceM;
  } else {
    const Eigen::Vector2d end = route.waypoints().back().position;
    const double remaining = route.length_m() - (start_s_m_ + progress_m_);
    step.finished = remaining <= destination_radius_m_ &&
                    (Eigen::Vector2d(pose.x_m, pose.y_m) - end).norm() <= destination_radius_m_;
  }
  last_ = step;
  return step;
}

const Route& find_route(const std::vector<Route>& routes, std::string_view name) {
  for (const Route& route : routes) {
    if (route.name() == name) return route;
  }
  std::string known;
  for (const Route& route : routes) known += (known.empty() ? "" : ", ") + route.name();
  throw RouteError("unknown route '" + std::string(name) +
                   "'; known routes: " + (known.empty() ? std::string("none") : known));
}

std::vector<Route> build_routes(const RoadNetwork& net, const std::vector<RouteSpec>& specs) {
  std::vector<Route> routes;
  routes.reserve(specs.size());
  for (const RouteSpec& spec : specs) routes.emplace_back(net, spec);
  return routes;
}

}  // namespace indrive::env
