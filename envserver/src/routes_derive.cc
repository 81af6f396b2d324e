// Derivation of the four standard routes from any road network.
#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>
#include <map>
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

// A candidate route: its edges and its length.
struct Candidate {
  std::vector<int> edges;
  double length_m = 0.0;
};

// Chains of straight moves over edges that are themselves straight (no curve), one per start
// edge, longest first.
std::vector<Candidate> straight_candidates(const RoadNetwork& net, const EdgeGraph& graph) {
  constexpr double kMaxBendRad = 15.0 * M_PI / 180.0;
  std::vector<Candidate> candidates;
  for (int start = 0; start < static_cast<int>(graph.moves.size()); ++start) {
    if (net.edge(start).internal || net.edge(start).lanes.empty() ||
        graph.bend_rad[start] > kMaxBendRad) {
      continue;
    }
    std::vector<int> chain = {start};
    std::set<int> seen = {start};
    double length = graph.length_m[start];
    for (;;) {
      int next = -1;
      double step = 0.0;
      for (const Move& move : graph.moves[chain.back()]) {
        if (move.direction == TurnDirection::kStraight && graph.bend_rad[move.to] <= kMaxBendRad) {
          next = move.to;
          step = move.length_m;
          break;
        }
      }
      if (next < 0 || !seen.insert(next).second) break;
      chain.push_back(next);
      length += step;
    }
    candidates.push_back({std::move(chain), length});
  }
  // Longest first; ties keep the edge order (stable), so derivation is deterministic.
  std::stable_sort(
      candidates.begin(), candidates.end(),
      [](const Candidate& a, const Candidate& b) { return a.length_m > b.length_m + 1e-6; });
  return candidates;
}

// Shortest simple cycles using only `allowed` turns and, when required_mask is set, at least
// one right (bit 1) and one left (bit 2) turn: Dijkstra over (edge, turns-seen) from every
// edge gives the shortest such cycle through it. Distinct cycles, shortest first, each rotated
// to start on its longest edge, so a vehicle has a run-up before the first turn.
std::vector<Candidate> loop_candidates(const RoadNetwork& net, const EdgeGraph& graph,
                                       bool allow_right, bool allow_left, int required_mask) {
  const int n = static_cast<int>(graph.moves.size());
  std::vector<Candidate> candidates;
  std::set<std::vector<int>> found;  // cycles as sorted edge lists, to drop rotations
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
      if (d > dist[state]) continue;
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
    std::vector<int> sorted = cycle;
    std::sort(sorted.begin(), sorted.end());
    if (std::adjacent_find(sorted.begin(), sorted.end()) != sorted.end()) continue;  // not simple
    if (!found.insert(sorted).second) continue;  // the same cycle from another start
    auto longest = std::max_element(cycle.begin(), cycle.end(), [&](int a, int b) {
      return graph.length_m[a] < graph.length_m[b];
    });
    std::rotate(cycle.begin(), longest, cycle.end());
    candidates.push_back({std::move(cycle), dist[goal]});
  }
  std::stable_sort(candidates.begin(), candidates.end(),
                   [](const Candidate& a, const Candidate& b) { return a.length_m < b.length_m; });
  return candidates;
}

// What the set search needs of a candidate: the exit it takes from each approach, and the exit
// it takes at each junction layout (route_choices()), with whether one rule fits it at all.
struct Profile {
  std::map<std::string, std::string> exits;  // approach edge -> exit edge
  std::map<std::string, char> rule;          // layout -> exit code
  bool consistent = true;                    // never two exits at one layout
};

Profile profile_of(const RoadNetwork& net, const RouteSpec& spec) {
  Profile profile;
  for (auto& [approach, exit] : route_approaches(spec)) profile.exits.emplace(approach, exit);
  const auto rule = layout_rule_of(route_choices(net, {spec}));
  profile.consistent = rule.has_value();
  if (rule) profile.rule = *rule;
  return profile;
}

// Whether two maps agree wherever both have a key.
template <typename Map>
bool agree(const Map& a, const Map& b) {
  for (const auto& [key, value] : a) {
    const auto it = b.find(key);
    if (it != b.end() && it->second != value) return false;
  }
  return true;
}

// Candidates considered per route kind (in rank order): 48^4 sets at most, each a few bit
// operations, well under a second on any network.
constexpr size_t kCandidatesPerKind = 48;

struct SetSearch {
  bool found = false;         // some set is conflict-free
  std::vector<size_t> index;  // its candidate per kind
  int followed = 0;           // its layout bound (routes one rule follows)
};

// Searches every combination (one candidate per kind) in rank order for the conflict-free set
// with the highest layout bound; pairs are compared once. The bound of a set is its largest
// subset of consistent, pairwise rule-compatible routes (one rule follows a subset exactly
// when every pair of its routes agrees at every layout both meet).
SetSearch best_set(const std::vector<std::vector<Profile>>& profiles) {
  const size_t kinds = profiles.size();
  // free_of[a][b][i][j]: candidate i of kind a and j of kind b leave no approach by different
  // exits; same_rule[...]: they agree at every shared layout.
  using Table = std::vector<std::vector<char>>;
  std::vector<std::vector<Table>> free_of(kinds, std::vector<Table>(kinds));
  std::vector<std::vector<Table>> same_rule(kinds, std::vector<Table>(kinds));
  for (size_t a = 0; a < kinds; ++a) {
    for (size_t b = a + 1; b < kinds; ++b) {
      free_of[a][b].assign(profiles[a].size(), std::vector<char>(profiles[b].size()));
      same_rule[a][b].assign(profiles[a].size(), std::vector<char>(profiles[b].size()));
      for (size_t i = 0; i < profiles[a].size(); ++i) {
        for (size_t j = 0; j < profiles[b].size(); ++j) {
          free_of[a][b][i][j] = agree(profiles[a][i].exits, profiles[b][j].exits);
          same_rule[a][b][i][j] = agree(profiles[a][i].rule, profiles[b][j].rule);
        }
      }
    }
  }
  SetSearch best;
  std::vector<size_t> index(kinds, 0);
  const auto bound_of = [&] {
    int most = 0;
    for (unsigned subset = 1; subset < (1u << kinds); ++subset) {
      const int size = __builtin_popcount(subset);
      if (size <= most) continue;
      bool ok = true;
      for (size_t a = 0; a < kinds && ok; ++a) {
        if (!(subset & (1u << a))) continue;
        ok = profiles[a][index[a]].consistent;
        for (size_t b = a + 1; b < kinds && ok; ++b) {
          if (subset & (1u << b)) ok = same_rule[a][b][index[a]][index[b]];
        }
      }
      if (ok) most = size;
    }
    return most;
  };
  const std::function<bool(size_t)> search = [&](size_t kind) {
    if (kind == kinds) {
      const int followed = bound_of();
      if (!best.found || followed > best.followed) best = SetSearch{true, index, followed};
      return best.followed == static_cast<int>(kinds);  // nothing can beat all routes
    }
    for (size_t c = 0; c < profiles[kind].size(); ++c) {
      bool fits = true;
      for (size_t earlier = 0; earlier < kind && fits; ++earlier) {
        fits = free_of[earlier][kind][index[earlier]][c];
      }
      if (!fits) continue;
      index[kind] = c;
      if (search(kind + 1)) return true;
    }
    return false;
  };
  search(0);
  return best;
}

RouteSpec to_spec(const RoadNetwork& net, std::string name, bool loop,
                  const std::vector<int>& edges) {
  RouteSpec spec{std::move(name), loop, {}};
  for (int e : edges) spec.edges.push_back(net.edge(e).id);
  return spec;
}

}  // namespace

std::vector<RouteSpec> derive_routes(const RoadNetwork& net, const RouteFilter& usable,
                                     std::vector<DroppedRoute>* dropped) {
  const EdgeGraph graph = make_graph(net);
  std::vector<std::vector<Candidate>> candidates = {
      straight_candidates(net, graph), loop_candidates(net, graph, true, false, 0),
      loop_candidates(net, graph, false, true, 0), loop_candidates(net, graph, true, true, 3)};
  std::string missing;
  for (size_t k = 0; k < candidates.size(); ++k) {
    if (candidates[k].empty()) {
      missing += ' ';  // two appends: GCC 12 warns (-Wrestrict, a false positive) on " " + name
      missing += kRouteNames[k];
    }
  }
  if (!missing.empty()) {
    throw RouteError("network '" + net.source().string() + "' allows no route for:" + missing +
                     "; use a network with closed blocks (loops need a ring of junctions) or "
                     "write a route file");
  }
  if (usable) {
    // Only candidates that pass, in rank order, up to the number the set search considers.
    std::string none_usable;
    for (size_t kind = 0; kind < candidates.size(); ++kind) {
      std::vector<Candidate> kept;
      std::string first_reason;
      for (const Candidate& candidate : candidates[kind]) {
        if (kept.size() == kCandidatesPerKind) break;
        const RouteSpec spec =
            to_spec(net, std::string(kRouteNames[kind]), kind > 0, candidate.edges);
        std::string reason = usable(spec);
        if (reason.empty()) {
          kept.push_back(candidate);
          continue;
        }
        if (first_reason.empty()) first_reason = reason;
        if (dropped != nullptr) dropped->push_back({spec, std::move(reason)});
      }
      if (kept.empty()) {
        none_usable += std::string(none_usable.empty() ? "" : "; ") +
                       std::string(kRouteNames[kind]) + " (" +
                       std::to_string(candidates[kind].size()) +
                       " candidates, the first: " + first_reason + ")";
      }
      candidates[kind] = std::move(kept);
    }
    if (!none_usable.empty()) {
      throw RouteError("network '" + net.source().string() +
                       "' has no route the scripted follower can drive for: " + none_usable +
                       "; write a route file for it");
    }
  }
  // The set a route-blind policy can follow best: among the conflict-free sets of candidates
  // (the first kCandidatesPerKind of each kind in rank order), one with the highest layout
  // bound (layout_rule_bound(): the most routes one layout -> exit rule follows), the first in
  // rank order among equals, so the best straight corridor (longest) and loops (shortest) are
  // kept unless a later candidate lets a policy follow more routes. When no set is
  // conflict-free the best candidate of each kind is kept and route_conflicts() reports the
  // clashes.
  const auto spec_of = [&](size_t kind, const Candidate& candidate) {
    return to_spec(net, std::string(kRouteNames[kind]), kind > 0, candidate.edges);
  };
  const size_t kinds = candidates.size();
  std::vector<std::vector<Profile>> profiles(kinds);
  for (size_t kind = 0; kind < kinds; ++kind) {
    const size_t count = std::min(candidates[kind].size(), kCandidatesPerKind);
    for (size_t c = 0; c < count; ++c) {
      profiles[kind].push_back(profile_of(net, spec_of(kind, candidates[kind][c])));
    }
  }
  const SetSearch best = best_set(profiles);
  std::vector<RouteSpec> chosen;
  for (size_t kind = 0; kind < kinds; ++kind) {
    chosen.push_back(spec_of(kind, candidates[kind][best.found ? best.index[kind] : 0]));
  }
  return chosen;
}

}  // namespace indrive::env
