#include "indrive/envserver/route_check.h"

#include <cmath>
#include <cstdio>
#include <vector>

#include "indrive/envserver/ego.h"
#include "indrive/envserver/events.h"
#include "indrive/envserver/follower.h"

namespace indrive::env {

std::string oracle_drive_failure(const RoadNetwork& net, const RouteSpec& spec) {
  std::vector<Route> routes;
  try {
    routes = build_routes(net, {spec});
  } catch (const RouteError& error) {
    return std::string("does not fit the network: ") + error.what();
  }
  const Route& route = routes.front();
  const EgoParams ego;
  EventConfig rules;  // strict
  rules.dt_s = ego.dt_s;
  // The strict protocol's budget (actor::route_step_budget(): 5 steps per metre).
  rules.time_limit_steps = std::max(1, static_cast<int>(std::ceil(5.0 * route.length_m())));
  EventDetector events(net, rules, ego);
  events.reset(&route);
  RouteTracker tracker(route);
  tracker.reset();
  WaypointFollower follower(route, ego);
  follower.reset();
  const EgoModel model(ego);
  EgoState state{.pose = route.start_pose()};
  for (int step = 1;; ++step) {
    state = model.step(state, decode_action(follower.act(state)));
    const RouteStep progress = tracker.update(state.pose);
    const std::uint32_t bits = events.update({.ego = state,
                                              .others = {},
                                              .route_finished = progress.finished,
                                              .route_distance_m = progress.distance_to_route_m,
                                              .step = step});
    if (bits == 0) continue;
    const std::uint32_t failures = bits & kFailureEvents;
    if ((bits & kDestination) != 0 && failures == 0) return "";
    char where[96];
    std::snprintf(where, sizeof where, " at %.0f%% of the route (step %d)",
                  100.0 * std::clamp(progress.progress_m / route.length_m(), 0.0, 1.0), step);
    return event_names(failures != 0 ? failures : bits) + where;
  }
}

}  // namespace indrive::env
