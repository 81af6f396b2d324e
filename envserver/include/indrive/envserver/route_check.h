// Whether the scripted route follower can drive a route: the check behind derived routes.
//
// A route derived from a map (derive_routes()) is kept only if the follower the evaluations
// use as their oracle (WaypointFollower at 5 m/s) drives it from its start to its end, alone
// on the road, without a failure event under the strict rules, within the strict protocol's
// budget of 5 steps per metre. No SUMO runs: without traffic the ego's model, the route
// tracker and the event detector decide every event.
//
//   const std::string why = oracle_drive_failure(net, spec);  // "" when drivable
#pragma once

#include <string>

#include "indrive/envserver/net.h"
#include "indrive/envserver/routes.h"

namespace indrive::env {

// "" when the follower completes the route; otherwise why not, e.g. "lane_invasion at 25% of
// the route (step 180)" or "does not fit the network: ...".
std::string oracle_drive_failure(const RoadNetwork& net, const RouteSpec& spec);

}  // namespace indrive::env
