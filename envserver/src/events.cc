#include "indrive/envserver/events.h"

#include <array>
#include <cmath>
#include <numbers>

#include "indrive/basics/check.h"

namespace indrive::env {
namespace {

std::array<Eigen::Vector2d, 4> corners(const Box& box) {
  const Eigen::Vector2d c(box.pose.x_m, box.pose.y_m);
  const Eigen::Vector2d f(std::cos(box.pose.yaw_rad), std::sin(box.pose.yaw_rad));
  const Eigen::Vector2d l(-f.y(), f.x());
  const Eigen::Vector2d hf = 0.5 * box.length_m * f;
  const Eigen::Vector2d hl = 0.5 * box.width_m * l;
  return {c + hf + hl, c + hf - hl, c - hf - hl, c - hf + hl};
}

// True when the projections of both corner sets on the axis are disjoint.
bool separated_on(const Eigen::Vector2d& axis, const std::array<Eigen::Vector2d, 4>& a,
                  const std::array<Eigen::Vector2d, 4>& b) {
  double a_min = INFINITY, a_max = -INFINITY, b_min = INFINITY, b_max = -INFINITY;
  for (int i = 0; i < 4; ++i) {
    const double pa = axis.dot(a[i]);
    const double pb = axis.dot(b[i]);
    a_min = std::min(a_min, pa);
    a_max = std::max(a_max, pa);
    b_min = std::min(b_min, pb);
    b_max = std::max(b_max, pb);
  }
  return a_max < b_min || b_max < a_min;
}

}  // namespace

const char* event_name(EventBit bit) {
  switch (bit) {
    case kCollision:
      return "collision";
    case kLaneInvasion:
      return "lane_invasion";
    case kWrongDirection:
      return "wrong_direction";
    case kOffRoad:
      return "off_road";
    case kStall:
      return "stall";
    case kDestination:
      return "destination";
    case kTimeLimit:
      return "time_limit";
    case kOffRoute:
      return "off_route";
    case kOutOfLane:
      return "out_of_lane";
    case kTooSlow:
      return "too_slow";
    case kEnvFault:
      return "env_fault";
  }
  return "unknown";
}

std::string event_names(std::uint32_t bits) {
  if (bits == 0) return "none";
  std::string names;
  for (int i = 0; i < kNumEvents; ++i) {
    const auto bit = static_cast<EventBit>(1u << i);
    if ((bits & bit) == 0) continue;
    if (!names.empty()) names += '+';
    names += event_name(bit);
  }
  return names;
}

bool boxes_overlap(const Box& a, const Box& b) {
  // Quick reject on the circumscribed circles: most pairs are far apart.
  const double dx = a.pose.x_m - b.pose.x_m;
  const double dy = a.pose.y_m - b.pose.y_m;
  const double reach =
      0.5 * (std::hypot(a.length_m, a.width_m) + std::hypot(b.length_m, b.width_m));
  if (dx * dx + dy * dy > reach * reach) return false;
  const auto ca = corners(a);
  const auto cb = corners(b);
  // Two rectangles are disjoint iff one of their four edge normals separates them.
  for (const Box* box : {&a, &b}) {
    const Eigen::Vector2d f(std::cos(box->pose.yaw_rad), std::sin(box->pose.yaw_rad));
    if (separated_on(f, ca, cb)) return false;
    if (separated_on(Eigen::Vector2d(-f.y(), f.x()), ca, cb)) return false;
  }
  return true;
}

EventDetector::EventDetector(const RoadNetwork& net, const EventConfig& config,
                             const EgoParams& ego)
    : net_(&net), config_(config), ego_(ego) {
  INDRIVE_CHECK(config.dt_s > 0.0) << "event dt must be positive";
  INDRIVE_CHECK(config.time_limit_steps > 0) << "time limit must be positive";
}

void EventDetector::reset(const Route* route) {
  slow_steps_ = 0;
  wrong_way_steps_ = 0;
  lane_invasions_ = 0;
  invading_ = false;
  route_ = route;
  route_edges_.assign(route != nullptr ? net_->edges().size() : 0, false);
  if (route != nullptr) {
    for (int lane : route->lanes()) {
      INDRIVE_CHECK(lane >= 0 && lane < static_cast<int>(net_->lanes().size()))
          << "route '" << route->name() << "' is not of this network";
      route_edges_[net_->lane(lane).edge] = true;
    }
  }
  road_ = RoadStatus{};
  sumo_only_collision_ = false;
}

RoadStatus EventDetector::road_status(const Pose2& pose) const {
  RoadStatus status;
  const Eigen::Vector2d centre(pose.x_m, pose.y_m);
  status.drivable = net_->is_drivable(centre);
  status.in_junction = net_->in_junction(centre);
  if (const auto at = net_->locate(centre, pose.yaw_rad)) {
    status.lane = at->lane;
    status.lateral_m = at->lateral_m;
    status.heading_error_rad = wrap_angle(pose.yaw_rad - at->heading_rad);
    status.in_junction = status.in_junction || net_->lane(at->lane).internal;
  }
  return status;
}

std::uint32_t EventDetector::update(const Inputs& in) {
  std::uint32_t bits = 0;

  // Collision: only a physical overlap of the ego's footprint with another car's box counts.
  // SUMO's own report checks its mirrored copy of the ego against internal-lane shapes, which
  // fires at junctions without any contact, so it is kept only as a diagnostic.
  const Box ego_box{SemanticClass::kVehicle, in.ego.pose, ego_.length_m, ego_.width_m,
                    ego_.height_m};
  bool hit = false;
  for (const Box& other : in.others) {
    if (hit) break;
    hit = boxes_overlap(ego_box, other);
  }
  if (hit) bits |= kCollision;
  sumo_only_collision_ = in.sumo_collision && !hit;

  // Road rules.
  road_ = road_status(in.ego.pose);
  if (!road_.drivable) bits |= kOffRoad;
  bool invading = false;
  if (road_.lane >= 0 && !road_.in_junction) {
    const double lane_width = net_->lane(road_.lane).width_m;
    const double beyond_marking = std::abs(road_.lateral_m) + 0.5 * ego_.width_m - 0.5 * lane_width;
    invading = beyond_marking > config_.lane_invasion_overlap_m;
  }
  if (invading && !invading_) ++lane_invasions_;
  invading_ = invading;
  if (config_.rules == EventRules::kIndriveCode) return update_indrive_code(in, bits);
  if (road_.lane >= 0 && !road_.in_junction) {
    if (invading) bits |= kLaneInvasion;
    if (std::abs(road_.heading_error_rad) >
        config_.wrong_direction_deg * std::numbers::pi / 180.0) {
      bits |= kWrongDirection;
    }
    // Off the route: on an edge the route does not drive (a lane change within a route edge
    // is not), or too far from its centre line. Internal lanes and junctions are exempt, so
    // the crossing itself never fires; the first lane after a wrong turn does.
    if (route_ != nullptr) {
      const Lane& lane = net_->lane(road_.lane);
      if (!route_edges_[lane.edge] ||
          in.route_distance_m > lane.width_m + config_.off_route_margin_m) {
        bits |= kOffRoute;
      }
    }
  }

  // Stall: too slow for too long, counted in whole steps.
  slow_steps_ = in.ego.speed_mps < config_.stall_speed_mps ? slow_steps_ + 1 : 0;
  if (slow_steps_ * config_.dt_s >= config_.stall_time_s - 1e-9) bits |= kStall;

  if (in.route_finished) bits |= kDestination;
  if (in.step >= config_.time_limit_steps) bits |= kTimeLimit;
  return bits;
}

std::uint32_t EventDetector::update_indrive_code(const Inputs& in, std::uint32_t bits) {
  const IndriveCodeRules& code = config_.code;
  const Eigen::Vector2d centre(in.ego.pose.x_m, in.ego.pose.y_m);

  // The nearest lane, normal or internal (the code projects onto the road): the one whose
  // centre line is nearest relative to its width. Farther than 2 m beyond every lane's edge
  // there is none, and the ego is out of lane.
  const LanePosition* nearest = nullptr;
  double nearest_fraction = INFINITY;
  const std::vector<LanePosition> around = net_->lanes_at(centre, 2.0);
  for (const LanePosition& at : around) {
    const double fraction = std::abs(at.lateral_m) / net_->lane(at.lane).width_m;
    if (fraction < nearest_fraction) {
      nearest_fraction = fraction;
      nearest = &at;
    }
  }
  if (nearest_fraction > code.out_of_lane_fraction) bits |= kOutOfLane;

  // Wrong direction: against the nearest lane (where the code's planner takes its next
  // waypoint), fast enough, for long enough.
  const bool wrong_way = nearest != nullptr &&
                         in.ego.speed_mps > code.wrong_direction_min_speed_mps &&
                         std::abs(wrap_angle(in.ego.pose.yaw_rad - nearest->heading_rad)) >
                             code.wrong_direction_deg * std::numbers::pi / 180.0;
  wrong_way_steps_ = wrong_way ? wrong_way_steps_ + 1 : 0;
  if (wrong_way_steps_ >= code.wrong_direction_steps) bits |= kWrongDirection;

  // Too slow, after a grace period.
  const bool slow =
      in.step > code.too_slow_grace_steps && in.ego.speed_mps < code.too_slow_speed_mps;
  slow_steps_ = slow ? slow_steps_ + 1 : 0;
  if (slow_steps_ >= code.too_slow_steps) bits |= kTooSlow;

  if (route_ != nullptr && (centre - route_->destination()).norm() <= code.destination_m) {
    bits |= kDestination;
  }
  if (in.step >= config_.time_limit_steps) bits |= kTimeLimit;
  return bits;
}

}  // namespace indrive::env
