// Point-to-point routes given by their end points: CARLA coordinates mapped into the network,
// and the shortest drivable path between two points.
#include <cmath>
#include <cstdio>
#include <limits>
#include <queue>

#include "indrive/envserver/routes.h"

namespace indrive::env {

namespace {

std::string point_text(const Eigen::Vector2d& p) {
  char text[64];
  std::snprintf(text, sizeof text, "(%.2f, %.2f)", p.x(), p.y());
  return text;
}

// The normal lanes whose surface holds `point` (within margin_m of their edge), heading within
// 90 degrees of `heading_rad` when given.
std::vector<LanePosition> normal_lanes_at(const RoadNetwork& net, const Eigen::Vector2d& point,
                                          std::optional<double> heading_rad, double margin_m) {
  std::vector<LanePosition> found;
  for (const LanePosition& at : net.lanes_at(point, margin_m)) {
    if (net.lane(at.lane).internal) continue;
    if (heading_rad && std::abs(wrap_angle(at.heading_rad - *heading_rad)) >= 0.5 * M_PI) continue;
    found.push_back(at);
  }
  return found;
}

// Length of a move across a junction: its internal lanes.
double crossing_length(const RoadNetwork& net, const Connection& connection) {
  double length = 0.0;
  for (int lane : net.crossing_lanes(connection)) length += net.lane(lane).length_m;
  return length;
}

}  // namespace

Eigen::Vector2d carla_to_network(const RoadNetwork& net, const Eigen::Vector2d& carla) {
  return Eigen::Vector2d(carla.x(), -carla.y()) + net.offset();
}

PointPath route_edges_between(const RoadNetwork& net, const Eigen::Vector2d& start,
                              const Eigen::Vector2d& end, std::optional<double> start_heading_rad,
                              std::optional<double> end_heading_rad, double margin_m) {
  const auto starts = normal_lanes_at(net, start, start_heading_rad, margin_m);
  const auto ends = normal_lanes_at(net, end, end_heading_rad, margin_m);
  for (const auto& [points, name] : {std::pair{&starts, "start"}, std::pair{&ends, "end"}}) {
    if (points->empty()) {
      const Eigen::Vector2d& p = std::string_view(name) == "start" ? start : end;
      throw RouteError(std::string("the ") + name + " point " + point_text(p) +
                       " (network frame) lies on no normal lane of '" + net.source().string() +
                       "' that runs its way; give a point on a road outside junctions (CARLA "
                       "coordinates: use carla_start / carla_end)");
    }
  }

  // Dijkstra over lanes from every start lane at once: the cost of a lane is the distance
  // driven to reach its start (the start lanes: from the start point, negative offset).
  const int lane_count = static_cast<int>(net.lanes().size());
  constexpr double kInf = std::numeric_limits<double>::infinity();
  std::vector<double> cost(lane_count, kInf);
  std::vector<int> previous(lane_count, -1);
  using Item = std::pair<double, int>;
  std::priority_queue<Item, std::vector<Item>, std::greater<>> queue;
  for (const LanePosition& at : starts) {
    cost[at.lane] = -at.s_m;
    queue.emplace(-at.s_m, at.lane);
  }
  PointPath best;
  double best_length = kInf;
  while (!queue.empty()) {
    const auto [c, lane] = queue.top();
    queue.pop();
    if (c > cost[lane]) continue;
    for (const LanePosition& at : ends) {
      if (at.lane != lane) continue;
      const double length = c + at.s_m;
      // On the start lane itself the end must lie ahead of the start.
      if (length > 0.5 && length < best_length) {
        best_length = length;
        best.end_lane = lane;
        best.end_s_m = at.s_m;
      }
    }
    const double leave = c + net.lane(lane).length_m;
    if (leave >= best_length) continue;
    for (int index : net.connections_from(lane)) {
      const Connection& connection = net.connections()[index];
      if (connection.direction == TurnDirection::kTurnaround) continue;
      const double next = leave + crossing_length(net, connection);
      if (next < cost[connection.to_lane]) {
        cost[connection.to_lane] = next;
        previous[connection.to_lane] = lane;
        queue.emplace(next, connection.to_lane);
      }
    }
  }
  if (best.end_lane < 0) {
    throw RouteError("no drivable path from " + point_text(start) + " to " + point_text(end) +
                     " (network frame) in '" + net.source().string() +
                     "'; check that the points lie on roads joined by permitted moves");
  }
  std::vector<int> lanes;
  for (int lane = best.end_lane; lane >= 0; lane = previous[lane])
    lanes.insert(lanes.begin(), lane);
  best.start_lane = lanes.front();
  for (const LanePosition& at : starts) {
    if (at.lane == best.start_lane) best.start_s_m = at.s_m;
  }
  for (int lane : lanes) best.edges.push_back(net.edge(net.lane(lane).edge).id);
  best.length_m = best_length;
  return best;
}

}  // namespace indrive::env
