// Episode events, checked every step and reported as bits.
//
// Every event ends the episode. All but kDestination are failures (logged as the failure
// reason). kTimeLimit is a truncation: the episode stops but the state is not terminal for the
// world model's continuation target; every other event is terminal.
//
//   collision        the ego's box overlaps another vehicle's box (oriented boxes); a collision
//                    SUMO reports without such an overlap is only a diagnostic
//                    (EventDetector::sumo_only_collision())
//   lane_invasion    outside junctions, more than lane_invasion_overlap_m of the ego's width
//                    lies beyond its lane's marking: |lateral| + w/2 - lane_w/2 > overlap
//   wrong_direction  outside junctions, heading differs from the lane's by more than 90 deg
//   off_road         the ego's footprint centre is on no lane and in no junction
//   off_route        only on a route (evaluation, task phases): outside junctions, the ego is on
//                    a normal lane of an edge the route does not drive (it took a turn the route
//                    does not take), or farther than the lane's width plus off_route_margin_m
//                    from the route's centre line; never without a route (pretraining)
//   stall            speed under 1 km/h for 60 s in a row
//   destination      within kDestinationRadiusM (10 m) of a point-to-point route's terminal
//                    waypoint, or the loop's lap completed (from the route tracker)
//   time_limit       the episode reached its step limit (EventConfig::time_limit_steps; the
//                    evaluator sets a per-route budget instead, 5 steps per metre of route)
//
// Those are the strict rules (EventRules::kStrict), ours everywhere. Evaluation can instead
// judge by the public InDRiVE code's rules (EventRules::kIndriveCode, eval.protocol:
// indrive_code; docs/evaluation.md), where an episode ends only on
//   collision        as above
//   out_of_lane      the ego's centre lies farther than 0.45 x the lane's width from the centre
//                    line of the nearest lane (normal or internal), or on no lane at all
//   off_road         the ego's centre is on no lane and in no junction (as above)
//   wrong_direction  faster than 0.5 m/s with the heading more than 120 deg from the nearest
//                    lane's, for 2,000 steps in a row
//   too_slow         slower than 0.01 m/s for 2,000 steps in a row after the first 2,000
//   destination      the ego's centre within 2.0 m of the route's end point
//                    (Route::destination()), by any path
//   time_limit       the evaluator's budget
// Lane invasions (the strict rule's condition) are counted, each entry once
// (EventDetector::lane_invasions()), and end nothing; neither stall nor off_route applies.
//
//   EventDetector events(net, EventConfig{}, ego_params);
//   events.reset();
//   std::uint32_t bits = events.update({.ego = ego, .others = boxes, .step = t});
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "indrive/envserver/ego.h"
#include "indrive/envserver/net.h"
#include "indrive/envserver/routes.h"
#include "indrive/envserver/scene.h"

namespace indrive::env {

// Event bits; several may fire in one step.
enum EventBit : std::uint32_t {
  kCollision = 1u << 0,
  kLaneInvasion = 1u << 1,
  kWrongDirection = 1u << 2,
  kOffRoad = 1u << 3,
  kStall = 1u << 4,
  kDestination = 1u << 5,
  kTimeLimit = 1u << 6,
  kOffRoute = 1u << 7,
  kOutOfLane = 1u << 8,  // the public InDRiVE code's rules only
  kTooSlow = 1u << 9,    // the public InDRiVE code's rules only
  // SUMO failed mid-episode (Env::step caught its error; the simulation is restarted at the
  // next reset). Neither a failure of the policy nor terminal: the episode is cut short, and
  // evaluations count it apart from the policy's episodes.
  kEnvFault = 1u << 10,
};
inline constexpr int kNumEvents = 11;
inline constexpr std::uint32_t kFailureEvents = kCollision | kLaneInvasion | kWrongDirection |
                                                kOffRoad | kStall | kTimeLimit | kOffRoute |
                                                kOutOfLane | kTooSlow;
inline constexpr std::uint32_t kTerminalEvents = kCollision | kLaneInvasion | kWrongDirection |
                                                 kOffRoad | kStall | kDestination | kOffRoute |
                                                 kOutOfLane | kTooSlow;

// Returns the name of one event bit ("collision", ...), or "unknown".
const char* event_name(EventBit bit);
// Returns the names of all bits set, joined by '+' ("none" when zero).
std::string event_names(std::uint32_t bits);
// True when the bits end the episode.
inline bool ends_episode(std::uint32_t bits) { return bits != 0; }
// True when the episode ended in a terminal state (not a time-limit truncation alone).
inline bool is_terminal(std::uint32_t bits) { return (bits & kTerminalEvents) != 0; }
// True when any failure event fired.
inline bool is_failure(std::uint32_t bits) { return (bits & kFailureEvents) != 0; }

// Which rules end an episode (see the top of this file).
enum class EventRules { kStrict, kIndriveCode };

// The public InDRiVE code's thresholds (its evaluation blocks and the code's defaults).
struct IndriveCodeRules {
  double destination_m = 2.0;
  double out_of_lane_fraction = 0.45;  // of the nearest lane's width (0.5 x 0.9 in the code)
  double wrong_direction_deg = 120.0;
  double wrong_direction_min_speed_mps = 0.5;
  int wrong_direction_steps = 2000;
  double too_slow_speed_mps = 0.01;
  int too_slow_steps = 2000;
  int too_slow_grace_steps = 2000;
};

// Thresholds of the events.
struct EventConfig {
  EventRules rules = EventRules::kStrict;
  IndriveCodeRules code;
  double lane_invasion_overlap_m = 0.3;
  double wrong_direction_deg = 90.0;
  double stall_speed_mps = 1.0 / 3.6;
  double stall_time_s = 60.0;
  int time_limit_steps = 1000;
  double off_route_margin_m = 1.0;  // beyond one lane width from the route's centre line
  double dt_s = 0.1;
};

// True when two upright boxes' footprints overlap (separating-axis test on the rectangles).
bool boxes_overlap(const Box& a, const Box& b);

// What the ego's position means for the road rules, for logging and tests.
struct RoadStatus {
  bool drivable = false;
  bool in_junction = false;  // inside a junction polygon or on an internal lane
  int lane = -1;             // lane the ego is on (-1 off all lanes)
  double lateral_m = 0.0;    // signed offset from that lane's centre line
  double heading_error_rad = 0.0;
};

// Checks the events of each step. Keeps the stall timer between steps.
class EventDetector {
 public:
  // The network must outlive the detector.
  EventDetector(const RoadNetwork& net, const EventConfig& config, const EgoParams& ego);

  // Starts a new episode (clears the stall timer). With a route (which must outlive the
  // episode and come from the same network) off_route is checked; without one it never fires.
  void reset(const Route* route = nullptr);

  // What one step's check needs.
  struct Inputs {
    EgoState ego;
    std::span<const Box> others;    // other vehicles' boxes
    bool sumo_collision = false;    // SUMO listed a collision involving the ego (diagnostic only)
    bool route_finished = false;    // the route tracker reports the end / a completed lap
    double route_distance_m = 0.0;  // the route tracker's distance to the route centre line
    int step = 0;                   // steps taken in this episode, this one included
  };
  // Returns the event bits of this step.
  std::uint32_t update(const Inputs& inputs);
  // The road status computed in the last update().
  const RoadStatus& road() const { return road_; }
  // True when the last update() had a SUMO collision report but no box overlap (no event).
  bool sumo_only_collision() const { return sumo_only_collision_; }
  // Road status of an ego pose (no state).
  RoadStatus road_status(const Pose2& pose) const;
  // Lane invasions since reset(): entries into the strict rule's lane_invasion condition. Under
  // the public InDRiVE code's rules they end nothing and are only counted; under the strict
  // rules the first ends the episode.
  int lane_invasions() const { return lane_invasions_; }

  const EventConfig& config() const { return config_; }

 private:
  const RoadNetwork* net_;
  EventConfig config_;
  EgoParams ego_;
  // The public InDRiVE code's rules (update_indrive_code()).
  std::uint32_t update_indrive_code(const Inputs& inputs, std::uint32_t bits);

  int slow_steps_ = 0;
  int wrong_way_steps_ = 0;
  int lane_invasions_ = 0;
  bool invading_ = false;
  const Route* route_ = nullptr;
  std::vector<bool> route_edges_;  // per network edge: the route drives it
  RoadStatus road_;
  bool sumo_only_collision_ = false;
};

}  // namespace indrive::env
