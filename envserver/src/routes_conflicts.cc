// The conflict rule of a town's routes: no approach may be left by two different exits; and
// the stricter layout bound: what a policy deciding by a junction's exits alone can follow.
#include <algorithm>
#include <map>
#include <set>
#include <utility>

#include "indrive/envserver/routes.h"

namespace indrive::env {
namespace {

std::vector<RouteSpec> specs_of(const std::vector<Route>& routes) {
  std::vector<RouteSpec> specs;
  specs.reserve(routes.size());
  for (const Route& route : routes) specs.push_back(route.spec());
  return specs;
}

}  // namespace

std::vector<std::pair<std::string, std::string>> route_approaches(const RouteSpec& spec) {
  const size_t n = spec.edges.size();
  const size_t pairs = spec.loop ? n : (n == 0 ? 0 : n - 1);
  std::vector<std::pair<std::string, std::string>> approaches;
  approaches.reserve(pairs);
  for (size_t i = 0; i < pairs; ++i)
    approaches.emplace_back(spec.edges[i], spec.edges[(i + 1) % n]);
  return approaches;
}

std::vector<RouteConflict> route_conflicts(const std::vector<RouteSpec>& specs) {
  struct Seen {
    std::string route;
    std::string exit;
  };
  std::map<std::string, Seen> first_exit;                  // per approach edge
  std::set<std::pair<std::string, std::string>> reported;  // (approach, clashing exit)
  std::vector<RouteConflict> conflicts;
  for (const RouteSpec& spec : specs) {
    for (const auto& [approach, exit] : route_approaches(spec)) {
      const auto [it, inserted] = first_exit.emplace(approach, Seen{spec.name, exit});
      if (inserted || it->second.exit == exit) continue;
      if (!reported.emplace(approach, exit).second) continue;
      RouteConflict conflict;
      conflict.approach = approach;
      conflict.route_a = it->second.route;
      conflict.exit_a = it->second.exit;
      conflict.route_b = spec.name;
      conflict.exit_b = exit;
      conflict.message = "approach " + approach + ": " + conflict.route_a + " leaves it to " +
                         conflict.exit_a + ", " + conflict.route_b + " to " + conflict.exit_b +
                         " (a policy that sees no route cannot follow both)";
      conflicts.push_back(std::move(conflict));
    }
  }
  return conflicts;
}

std::vector<RouteConflict> route_conflicts(const std::vector<Route>& routes) {
  return route_conflicts(specs_of(routes));
}

namespace {

// 'l', 'r' or 's' for a move; U-turns give 0 (no exit a route takes or a policy is offered).
char exit_code(TurnDirection direction) {
  if (direction == TurnDirection::kTurnaround) return 0;
  if (is_left_turn(direction)) return 'l';
  if (is_right_turn(direction)) return 'r';
  return 's';
}

std::string describe_exit(char code) {
  switch (code) {
    case 'l':
      return "turns left";
    case 'r':
      return "turns right";
    default:
      return "goes straight";
  }
}

}  // namespace

std::vector<RouteChoice> route_choices(const RoadNetwork& net,
                                       const std::vector<RouteSpec>& specs) {
  std::vector<RouteChoice> choices;
  for (const RouteSpec& spec : specs) {
    for (const auto& [approach, exit] : route_approaches(spec)) {
      const int edge = net.find_edge(approach);
      if (edge < 0) throw RouteError("route " + spec.name + ": no edge '" + approach + "'");
      std::map<std::string, char> exits;  // exit edge id -> direction code
      for (int lane : net.edge(edge).lanes) {
        for (int c : net.connections_from(lane)) {
          const Connection& connection = net.connections()[c];
          const char code = exit_code(connection.direction);
          if (code == 0) continue;
          exits.emplace(net.edge(net.lane(connection.to_lane).edge).id, code);
        }
      }
      const auto taken = exits.find(exit);
      if (taken == exits.end()) {
        throw RouteError("route " + spec.name + ": edge '" + approach + "' does not lead to '" +
                         exit + "'");
      }
      std::string layout;
      for (const auto& [id, code] : exits) {
        if (layout.find(code) == std::string::npos) layout += code;
      }
      if (layout.size() < 2) continue;  // one way on: no choice
      std::sort(layout.begin(), layout.end());
      choices.push_back(RouteChoice{spec.name, approach, layout, taken->second});
    }
  }
  return choices;
}

std::vector<RouteChoice> route_choices(const RoadNetwork& net, const std::vector<Route>& routes) {
  return route_choices(net, specs_of(routes));
}

std::optional<std::map<std::string, char>> layout_rule_of(const std::vector<RouteChoice>& choices) {
  std::map<std::string, char> rule;
  for (const RouteChoice& choice : choices) {
    const auto [it, inserted] = rule.emplace(choice.layout, choice.taken);
    if (!inserted && it->second != choice.taken) return std::nullopt;
  }
  return rule;
}

LayoutRuleBound layout_rule_bound(const std::vector<std::string>& names,
                                  const std::vector<RouteChoice>& choices) {
  std::vector<std::string> routes = names;
  for (const RouteChoice& choice : choices) {
    if (std::find(routes.begin(), routes.end(), choice.route) == routes.end()) {
      routes.push_back(choice.route);
    }
  }
  const int n = static_cast<int>(routes.size());
  if (n > 20) throw RouteError("layout_rule_bound: more than 20 routes");
  // Each route's own rule; a route that takes two exits at one layout follows no rule.
  std::vector<std::vector<RouteChoice>> by_route(n);
  for (const RouteChoice& choice : choices) {
    by_route[std::find(routes.begin(), routes.end(), choice.route) - routes.begin()].push_back(
        choice);
  }
  std::vector<std::map<std::string, char>> own(n);
  std::vector<bool> consistent(n, true);
  for (int r = 0; r < n; ++r) {
    const auto rule = layout_rule_of(by_route[r]);
    consistent[r] = rule.has_value();
    if (rule) own[r] = *rule;
  }
  LayoutRuleBound bound;
  bound.route_count = n;
  int best_size = -1;
  for (unsigned subset = 0; subset < (1u << n); ++subset) {
    const int size = __builtin_popcount(subset);
    if (size <= best_size) continue;
    std::map<std::string, char> rule;
    bool ok = true;
    for (int r = 0; r < n && ok; ++r) {
      if (!(subset & (1u << r))) continue;
      ok = consistent[r];
      for (const auto& [layout, taken] : own[r]) {
        const auto [it, inserted] = rule.emplace(layout, taken);
        if (!inserted && it->second != taken) ok = false;
      }
    }
    if (!ok) continue;
    best_size = size;
    bound.rule = rule;
    bound.routes_followed.clear();
    for (int r = 0; r < n; ++r) {
      if (subset & (1u << r)) bound.routes_followed.push_back(routes[r]);
    }
  }
  // Look-alikes: per layout, the routes' exits, when they differ.
  std::map<std::string, std::vector<const RouteChoice*>> by_layout;
  for (const RouteChoice& choice : choices) by_layout[choice.layout].push_back(&choice);
  for (const auto& [layout, list] : by_layout) {
    std::set<char> exits;
    for (const RouteChoice* choice : list) exits.insert(choice->taken);
    if (exits.size() < 2) continue;
    std::string line = "{";
    for (size_t i = 0; i < layout.size(); ++i) {
      if (i > 0) line += ',';
      line += layout[i];
    }
    line += "}:";
    std::set<std::pair<std::string, char>> said;
    for (const RouteChoice* choice : list) {
      if (!said.emplace(choice->route, choice->taken).second) continue;
      line += (said.size() > 1 ? ", " : " ") + choice->route + " " + describe_exit(choice->taken) +
              " (" + choice->approach + ")";
    }
    bound.lookalikes.push_back(line);
  }
  return bound;
}

}  // namespace indrive::env
