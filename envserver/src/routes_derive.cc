// Derivation of the four standard routes from any road network.
#include <algorithm>
#include <cmath>
#include <limits>
#include <queue>
#include <set>

#include "indrive/envserver/routes.h"

namespace indrive::env {

namespace {

// A move between two normal edges.
struct Move {
  int to = -1;
  TurnDirection direction = TurnDirection::kStraight;
  double length_m = 0.0;  // junction crossing plus the target edge
};

struct EdgeGraph {
  std::vector<std::vector<Move>> moves;  // per edge
  std::vector<double> length_m;          // per edge (its rightmost lane)
  std::vector<double> bend_rad;          // total heading change along the edge
};

EdgeGraph make_graph(const RoadNetwork& net) {
  EdgeGraph graph;
  const int n = static_cast<int>(net.edges().size());
  graph.moves.assign(n, {});
  graph.length_m.assign(n, 0.0);
  graph.bend_rad.assign(n, 0.0);
  for (int e = 0; e < n; ++e) {
    const Edge& edge = net.edge(e);
    if (edge.internal || edge.lanes.empty()) continue;
    const Lane& lane = net.lane(edge.lanes.front());
    graph.length_m[e] = lane.length_m;
    for (size_t i = 1; i + 1 < lane.shape.size(); ++i) {
      const Eigen::Vector2d a = lane.shape[i] - lane.shape[i - 1];
      const Eigen::Vector2d b = lane.shape[i + 1] - lane.shape[i];
      graph.bend_rad[e] +=
          std::abs(wrap_angle(std::atan2(b.y(), b.x()) - std::atan2(a.y(), a.x())));
    }
  }
  for (const Connection& connection : net.connections()) {
    const int from = net.lane(connection.from_lane).edge;
    const int to = net.lane(connection.to_lane).edge;
    if (connection.direction == TurnDirection::kTurnaround) continue;
    auto& moves = graph.moves[from];
    if (std::any_of(moves.begin(), moves.end(), [&](const Move& m) { return m.to == to; }))
      continue;
    double crossing = 0.0;
    for (int lane : net.crossing_lanes(connection)) crossing += net.lane(lane).length_m;
    moves.push_back(Move{to, connection.direction, crossing + graph.length_m[to]});
  }
  return graph;
}

// Longest chain of straight moves over edges that are themselves straight (no curve).
std::vector<int> longest_straight(const RoadNetwork& net, const EdgeGraph& graph) {
  constexpr double kMaxBendRad = 15.0 * M_PI / 180.0;
  std::vector<int> best;
  double best_length = 0.0;
  for (int start = 0; start < static_cast<int>(graph.moves.size()); ++start) {
    if (net.edge(start).internal || graph.bend_rad[start] > kMaxBendRad) continue;
    std::vector<int> chain = {start};
    std::set<int> seen = {start};
    double length = graph.length_m[start];
    for (;;) {
      int next = -1;
      for (const Move& move : graph.moves[chain.back()]) {
        if (move.direction == TurnDirection::kStraight && graph.bend_rad[move.to] <= kMaxBendRad) {
          next = move.to;
          length += move.length_m;
          break;
        }
      }
      if (next < 0 || !seen.insert(next).second) break;
      chain.push_back(next);
    }
    if (length > best_length + 1e-6) {
      best_length = length;
      best = chain;
    }
  }
  return best;
}

// Shortest simple cycle using only `allowed` turns and, when required_mask is set, at least one
// right (bit 1) and one left (bit 2) turn. Dijkstra over (edge, turns-seen) from every edge.
std::vector<int> shortest_loop(const RoadNetwork& net, const EdgeGraph& graph, bool allow_right,
                               bool allow_left, int required_mask) {
  const int n = static_cast<int>(graph.moves.size());
  std::vector<int> best;
  double best_length = std::numeric_limits<double>::infinity();
  for (int start = 0; start < n; ++start) {
    if (net.edge(start).internal || graph.moves[start].empty()) continue;
    const int states = n * 4;
    std::vector<double> dist(states, std::numeric_limits<double>::infinity());
    std::vector<int> previous(states, -1);
    using Item = std::pair<double, int>;
    std::priority_queue<Item, std::vector<Item>, std::greater<Item>> queue;
    dist[start * 4] = 0.0;
    queue.push({0.0, start * 4});
    int goal = -1;
    while (!queue.empty()) {
      const auto [d, state] = queue.top();
      queue.pop();
      if (d > dist[state] || d >= best_length) continue;
      const int edge = state / 4;
      const int mask = state % 4;
      if (edge == start && state != start * 4) {
        if ((mask & required_mask) == required_mask && mask != 0) {
          goal = state;
          break;
        }
        continue;
      }
      for (const Move& move : graph.moves[edge]) {
        int next_mask = mask;
        if (is_right_turn(move.direction)) {
          if (!allow_right) continue;
          next_mask |= 1;
        } else if (is_left_turn(move.direction)) {
          if (!allow_left) continue;
          next_mask |= 2;
        }
        const int next = move.to * 4 + next_mask;
        const double cost = d + move.length_m;
        if (cost < dist[next]) {
          dist[next] = cost;
          previous[next] = state;
          queue.push({cost, next});
        }
      }
    }
    if (goal < 0) continue;
    std::vector<int> cycle;
    for (int state = previous[goal]; state >= 0; state = previous[state]) {
      cycle.push_back(state / 4);
    }
    std::reverse(cycle.begin(), cycle.end());
    const std::set<int> unique(cycle.begin(), cycle.end());
    if (unique.size() != cycle.size()) continue;  // not a simple loop
    best_length = dist[goal];
    best = cycle;
  }
  // Start on the longest edge, so a vehicle has a run-up before the first turn.
  if (!best.empty()) {
    auto longest = std::max_element(best.begin(), best.end(), [&](int a, int b) {
      return graph.length_m[a] < graph.length_m[b];
    });
    std::rotate(best.begin(), longest, best.end());
  }
  return best;
}

RouteSpec to_spec(const RoadNetwork& net, std::string name, bool loop,
                  const std::vector<int>& edges) {
  RouteSpec spec{std::move(name), loop, {}};
  for (int e : edges) spec.edges.push_back(net.edge(e).id);
  return spec;
}

}  // namespace

std::vector<RouteSpec> derive_routes(const RoadNetwork& net) {
  const EdgeGraph graph = make_graph(net);
  const std::vector<int> straight = longest_straight(net, graph);
  const std::vector<int> right = shortest_loop(net, graph, true, false, 0);
  const std::vector<int> left = shortest_loop(net, graph, false, true, 0);
  const std::vector<int> mixed = shortest_loop(net, graph, true, true, 3);
  std::string missing;
  if (straight.empty()) missing += " straight";
  if (right.empty()) missing += " right_loop";
  if (left.empty()) missing += " left_loop";
  if (mixed.empty()) missing += " two_turn";
  if (!missing.empty()) {
    throw RouteError("network '" + net.source().string() + "' allows no route for:" + missing +
                     "; use a network with closed blocks (loops need a ring of junctions) or "
                     "write a route file");
  }
  return {to_spec(net, "straight", false, straight), to_spec(net, "right_loop", true, right),
          to_spec(net, "left_loop", true, left), to_spec(net, "two_turn", true, mixed)};
}

}  // namespace indrive::env
