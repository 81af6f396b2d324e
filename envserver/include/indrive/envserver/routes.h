// Routes: the four fixed paths a task is driven on, and a tracker of progress along one.
//
// Our towns have four routes of the paper's kinds: `straight` (point to point along a corridor,
// no turns), `right_loop` (closed loop of right turns only), `left_loop` (closed loop of left
// turns only) and `two_turn` (closed loop mixing left and right turns). Built-in towns ship
// them in a YAML file; for any other network derive_routes() finds them. CARLA's towns
// (carla_town01, carla_town02) ship the public InDRiVE code's routes instead: point-to-point
// segments given by their end points (straight_1, right_1, ..., two_turn_1). A Route is the lane
// sequence (internal junction lanes included) and dense waypoints every ~2 m.
//
//   std::vector<Route> routes = build_routes(net, read_route_file(path));
//   const Route& route = find_route(routes, "right_loop");   // throws RouteError if unknown
//   RouteTracker tracker(route);
//   tracker.reset();
//   RouteStep step = tracker.update(ego_pose);   // every env step
//   if (step.finished) { /* destination reached or loop completed */ }
#pragma once

#include <Eigen/Core>
#include <array>
#include <filesystem>
#include <functional>
#include <map>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "indrive/envserver/net.h"
#include "indrive/envserver/scene.h"

namespace indrive::env {

// A point-to-point route's destination is reached within this radius of its terminal
// waypoint (straight-line distance, once the tracker is that close along the route): the goal
// radius of the public InDRiVE code.
inline constexpr double kDestinationRadiusM = 10.0;
// A loop's lap is completed this close (along the route) to its start.
inline constexpr double kLapToleranceM = 3.0;
// A point-to-point route ends this far before the end of its last edge (at most half that
// edge), so its terminal waypoint lies before the stop line of the junction the edge runs
// into, not in that junction's approach.
inline constexpr double kRouteEndSetbackM = 20.0;

// The route names every town provides, in this order.
inline constexpr std::array<std::string_view, 4> kRouteNames = {"straight", "right_loop",
                                                                "left_loop", "two_turn"};

// An unknown route name, a route file that cannot be read, or a route that does not fit the
// network (edges not connected). The message lists what is known or what is wrong.
class RouteError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Where a point-to-point route's end points are given.
enum class PointFrame {
  kNetwork,  // SUMO's network frame (metres, x east, y north)
  kCarla,    // CARLA's world frame: x as the network's, y = -(network y), before the network's
             // offset (carla_to_network())
};

// A route as stored in a file: the normal edges it drives, in order. A loop's last edge
// connects back to its first.
//
// A point-to-point route may instead give its two end points (the public InDRiVE code's routes
// are CARLA world coordinates): the route is then the shortest drivable path from the lane the
// start point lies on to the lane the end point lies on (route_edges_between()), and it starts
// and ends at the points' projections onto those lanes' centre lines. `edges` may still be
// given; it must then be that path's edges.
struct RouteSpec {
  std::string name;
  bool loop = false;
  std::vector<std::string> edges;
  std::optional<Eigen::Vector2d> start;  // both or neither, never on a loop
  std::optional<Eigen::Vector2d> end;
  // Direction of travel at the points, when given (radians in `frame`: CARLA's yaw is clockwise,
  // so a CARLA yaw of 90 degrees is a network heading of -90): only lanes within 90 degrees of
  // it hold the point.
  std::optional<double> start_heading_rad;
  std::optional<double> end_heading_rad;
  PointFrame frame = PointFrame::kNetwork;
  std::string kind;  // a label written in the file (the code's "straight", "right", ...); free
};

// A CARLA world point in the network frame: CARLA's y axis is OpenDRIVE's -y, and netconvert
// shifts OpenDRIVE coordinates by the network's offset (RoadNetwork::offset()).
Eigen::Vector2d carla_to_network(const RoadNetwork& net, const Eigen::Vector2d& carla);

// The shortest drivable path between two points, as route_edges_between() finds it.
struct PointPath {
  std::vector<std::string> edges;  // normal edges, first to last
  int start_lane = -1;             // the lane of the first edge the start point lies on
  int end_lane = -1;               // the lane of the last edge the end point lies on
  double start_s_m = 0.0;          // the start point's arc length along start_lane
  double end_s_m = 0.0;            // the end point's arc length along end_lane
  double length_m = 0.0;           // driving distance from start to end
};
// Finds the shortest path of permitted moves (no U-turns) from a normal lane whose surface
// holds `start` (within `margin_m` of its edge) to one that holds `end`, over every such pair
// of lanes: on a two-way road that picks the lane whose direction leads to the end point.
// Given a heading at a point, only lanes within 90 degrees of it count there. Throws
// RouteError naming the point when no normal lane holds it or no path joins them.
PointPath route_edges_between(const RoadNetwork& net, const Eigen::Vector2d& start,
                              const Eigen::Vector2d& end,
                              std::optional<double> start_heading_rad = std::nullopt,
                              std::optional<double> end_heading_rad = std::nullopt,
                              double margin_m = 0.5);

// A point on the route's centre line.
struct Waypoint {
  Eigen::Vector2d position{0.0, 0.0};
  double heading_rad = 0.0;   // direction of travel
  double lane_width_m = 3.5;  // width of the lane the waypoint lies on
  double s_m = 0.0;           // arc length from the route start
  int lane = -1;              // index into RoadNetwork::lanes()
};

// The closest point of a route to a query point.
struct RoutePoint {
  double s_m = 0.0;        // arc length of the closest route point, in [0, length_m]
  double lateral_m = 0.0;  // signed offset from the route centre line, positive to the left
  double heading_rad = 0.0;
  double lane_width_m = 3.5;
};

// A fixed path through the network with dense waypoints. Self-contained: it copies what it
// needs from the network, so it outlives the RoadNetwork it was built from.
class Route {
 public:
  // Builds the route from a spec; throws RouteError when an edge is unknown, consecutive edges
  // are not connected, or a loop does not close. `spacing_m` is the waypoint spacing.
  Route(const RoadNetwork& net, const RouteSpec& spec, double spacing_m = 2.0);

  const std::string& name() const { return spec_.name; }
  bool is_loop() const { return spec_.loop; }
  const RouteSpec& spec() const { return spec_; }
  // The lanes driven, in order, internal junction lanes included (indices into the network).
  const std::vector<int>& lanes() const { return lanes_; }
  // Turn direction at each junction crossed, in driving order (a loop's closing junction last).
  const std::vector<TurnDirection>& turns() const { return turns_; }
  // Waypoints every ~spacing_m from the start; a loop's last waypoint lies before its start,
  // a point-to-point route's last (terminal) waypoint at length_m().
  const std::vector<Waypoint>& waypoints() const { return waypoints_; }
  // Total length of the centre line in metres (one lap for a loop; a point-to-point route's
  // ends kRouteEndSetbackM before the end of its last edge).
  double length_m() const { return length_m_; }
  // Pose at the first waypoint, facing along the route.
  Pose2 start_pose() const;
  // Where a point-to-point route ends: its end point as given (network frame) for a route
  // given by points, else its terminal waypoint; a loop's start.
  const Eigen::Vector2d& destination() const { return destination_; }
  // Pose on the route centre line at arc length s_m (wrapped for loops, clamped otherwise).
  Pose2 pose_at(double s_m) const;
  // Projects a point onto the centre line, searching only arc lengths within `window_m` of
  // `s_hint_m` (wrapping on loops); a negative window searches the whole route.
  RoutePoint project(const Eigen::Vector2d& point, double s_hint_m = 0.0,
                     double window_m = -1.0) const;
  // Index of the first waypoint strictly ahead of arc length s_m (wraps to 0 on loops; on a
  // point-to-point route the last waypoint once past it).
  int next_waypoint(double s_m) const;

 private:
  // Keeps the centre line between arc lengths from_s and to_s (from_s < to_s).
  void trim_line(double from_s, double to_s);

  RouteSpec spec_;
  std::vector<int> lanes_;
  std::vector<TurnDirection> turns_;
  std::vector<Eigen::Vector2d> line_;  // dense centre line
  std::vector<double> line_s_m_;       // arc length per centre-line point
  std::vector<double> line_width_m_;   // lane width per centre-line point
  std::vector<int> line_lane_;         // lane of the segment starting at each point
  std::vector<Waypoint> waypoints_;
  double length_m_ = 0.0;
  Eigen::Vector2d destination_{0.0, 0.0};
};

// What one tracker update reports.
struct RouteStep {
  double progress_m = 0.0;   // distance driven along the route since reset (unwrapped on loops)
  double delta_m = 0.0;      // change of progress_m in this update (negative when reversing)
  int waypoints_passed = 0;  // new waypoints passed in this update (never negative)
  int next_waypoint = 0;     // index into Route::waypoints()
  double lateral_m = 0.0;    // signed offset from the route centre line, positive to the left
  double distance_to_route_m = 0.0;  // |lateral_m|
  bool finished = false;  // within the destination radius of the terminal waypoint (point to
                          // point) or one lap completed (loop)
};

// Follows a vehicle along a route step by step. Searching near the last position keeps loops
// and routes that pass near themselves unambiguous.
class RouteTracker {
 public:
  // Tracks `route`, which must outlive the tracker. A point-to-point route is finished once
  // the vehicle is within `destination_radius_m` of its terminal waypoint, both along the route
  // and in a straight line; a loop once kLapToleranceM short of a full lap.
  explicit RouteTracker(const Route& route, double destination_radius_m = kDestinationRadiusM);
  // Restarts at arc length `s_m` (the route start by default).
  void reset(double s_m = 0.0);
  // Advances with the vehicle's new pose and reports progress.
  RouteStep update(const Pose2& pose);
  // The last report (all zero after reset).
  const RouteStep& last() const { return last_; }

 private:
  const Route* route_;
  double destination_radius_m_;
  double start_s_m_ = 0.0;
  double s_m_ = 0.0;              // current arc length on the route, wrapped for loops
  double progress_m_ = 0.0;       // unwrapped distance since reset
  double best_progress_m_ = 0.0;  // waypoints count only once: progress high-water mark
  RouteStep last_;
};

// Reads route specs from a YAML file: a map from route name to {loop: bool, edges: [ids]}, or,
// for a point-to-point route, {kind: label, start: [x, y], end: [x, y]} in the network frame or
// {kind: label, carla_start: [x, y], carla_end: [x, y]} in CARLA's world frame. Throws
// RouteError when the file is missing or malformed.
std::vector<RouteSpec> read_route_file(const std::filesystem::path& path);
// Writes route specs in the format read_route_file() reads.
void write_route_file(const std::filesystem::path& path, const std::vector<RouteSpec>& specs);
// Finds the four standard routes in any network: the longest straight corridor, the smallest
// loops of right turns (clockwise) and of left turns (counter-clockwise), and the smallest
// loop with both. Among the conflict-free sets (route_conflicts()) of the candidates (the
// first 48 of each kind in that order) it takes one whose layout bound (layout_rule_bound())
// is highest, the first in rank order among equals, so a policy that sees no route can follow
// as many as the network allows; the best candidate of each kind when no set is conflict-free.
// Throws RouteError naming the route kinds the network does not allow.
//
// With `usable`, a candidate is considered only if usable(spec) returns "" (otherwise the
// reason it is not, e.g. oracle_drive_failure()); candidates are tried in rank order until 48
// of a kind pass, and those that failed go to `dropped` with their reasons. A kind none of
// whose candidates passes is named in the RouteError with the first reasons.
using RouteFilter = std::function<std::string(const RouteSpec&)>;
struct DroppedRoute {
  RouteSpec spec;
  std::string reason;
};
std::vector<RouteSpec> derive_routes(const RoadNetwork& net, const RouteFilter& usable = {},
                                     std::vector<DroppedRoute>* dropped = nullptr);
// Builds a Route per spec; throws RouteError when a spec does not fit the network.
std::vector<Route> build_routes(const RoadNetwork& net, const std::vector<RouteSpec>& specs);
// Returns the route called `name`; throws RouteError listing the known names otherwise.
const Route& find_route(const std::vector<Route>& routes, std::string_view name);

// Two routes of a town that leave the same approach by different exits. The policy sees no
// route, only the camera, so on such an approach it cannot know which exit to take: the
// success rates of the two routes could not both reach 100 %.
struct RouteConflict {
  std::string approach;  // the incoming normal edge
  std::string route_a;   // the route met first (in spec order) ...
  std::string exit_a;    // ... and the edge it leaves the approach by
  std::string route_b;   // a later route (or route_a again, further on) ...
  std::string exit_b;    // ... leaving by another edge
  std::string message;   // one line naming all of the above
};
// The approaches a route drives, in order: each consecutive edge pair (approach edge, exit
// edge), a loop's closing pair (last -> first) included.
std::vector<std::pair<std::string, std::string>> route_approaches(const RouteSpec& spec);

// The conflicts of a set of routes. An approach is a consecutive edge pair (in -> out) of a
// route, a loop's closing pair (last -> first) included; the set is conflict-free when no
// incoming edge is left by two different exits across all routes. Each (approach, exit)
// clash is reported once, against the first exit seen.
std::vector<RouteConflict> route_conflicts(const std::vector<RouteSpec>& specs);
std::vector<RouteConflict> route_conflicts(const std::vector<Route>& routes);

// The stricter reading of "drivable by one policy that sees no route". The policy sees no
// edge id either: at a junction it sees which exits the junction offers (its layout: left,
// straight, right) and must choose one. Two routes that take different exits at junctions of
// the same layout are look-alikes: a policy that decides by the layout alone follows at most
// one of them, whatever it learned. (A camera policy may see more than the layout: the route
// probe, tools/route_probe/, measures whether a snapshot's inputs tell the places apart.)
//
// One choice a route makes: at the end of `approach` the junction offers `layout` (the turn
// directions of its exits, U-turns left out, partial turns counted as turns: a sorted string
// of 'l', 'r', 's', e.g. "rs") and the route takes `taken`. Only junctions that offer two or
// more exits are choices.
struct RouteChoice {
  std::string route;
  std::string approach;
  std::string layout;
  char taken = 's';
};
// Every choice of every route, in route and edge order (a loop's closing pair included).
// Throws RouteError when a route's consecutive edges are not connected in `net`.
std::vector<RouteChoice> route_choices(const RoadNetwork& net, const std::vector<RouteSpec>& specs);
std::vector<RouteChoice> route_choices(const RoadNetwork& net, const std::vector<Route>& routes);

// The layout -> exit rule (direction code) that `choices` make, all of them taken as one
// route's; nullopt when they take two exits at one layout (no rule follows such a route).
std::optional<std::map<std::string, char>> layout_rule_of(const std::vector<RouteChoice>& choices);

// What a policy deciding by junction layout alone can follow of a set of routes.
struct LayoutRuleBound {
  // A largest set of routes one layout -> exit rule follows (first such set in route order),
  // and that rule (layout -> direction code) restricted to the layouts those routes meet.
  std::vector<std::string> routes_followed;
  std::map<std::string, char> rule;
  int route_count = 0;  // routes considered (every route named in the choices or `names`)
  // One line per layout at which the routes take different exits, naming each route's exit
  // and one approach where it takes it, e.g. "{r,s}: straight goes straight (B1_M1), ...".
  std::vector<std::string> lookalikes;
};
// The bound for `names` (routes without a choice count as followed by any rule) given their
// choices; an exhaustive search over the 2^n route subsets (n <= 20, else RouteError).
LayoutRuleBound layout_rule_bound(const std::vector<std::string>& names,
                                  const std::vector<RouteChoice>& choices);

}  // namespace indrive::env
