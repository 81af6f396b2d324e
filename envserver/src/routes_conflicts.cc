// The conflict rule of a town's routes: no approach may be left by two different exits.
#include <map>
#include <set>
#include <utility>

#include "indrive/envserver/routes.h"

namespace indrive::env {

std::vector<RouteConflict> route_conflicts(const std::vector<RouteSpec>& specs) {
  struct Seen {
    std::string route;
    std::string exit;
  };
  std::map<std::string, Seen> first_exit;                  // per approach edge
  std::set<std::pair<std::string, std::string>> reported;  // (approach, clashing exit)
  std::vector<RouteConflict> conflicts;
  for (const RouteSpec& spec : specs) {
    const size_t n = spec.edges.size();
    const size_t pairs = spec.loop ? n : (n == 0 ? 0 : n - 1);
    for (size_t i = 0; i < pairs; ++i) {
      const std::string& approach = spec.edges[i];
      const std::string& exit = spec.edges[(i + 1) % n];
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
  std::vector<RouteSpec> specs;
  specs.reserve(routes.size());
  for (const Route& route : routes) specs.push_back(route.spec());
  return route_conflicts(specs);
}

}  // namespace indrive::env
