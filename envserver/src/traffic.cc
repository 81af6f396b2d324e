#include "indrive/envserver/traffic.h"

#include <algorithm>
#include <cmath>
#include <numbers>

#include "indrive/basics/check.h"
#include "indrive/basics/log.h"

namespace indrive::env {
namespace {

// Portable index draw (std::uniform_int_distribution differs between standard libraries).
std::size_t draw_index(std::mt19937_64& rng, std::size_t n) {
  INDRIVE_CHECK(n > 0) << "draw from an empty set";
  return static_cast<std::size_t>(rng() % n);
}

double distance(const Pose2& a, const Pose2& b) { return std::hypot(a.x_m - b.x_m, a.y_m - b.y_m); }

bool is_traffic(const std::string& id) { return id.rfind(TrafficManager::kIdPrefix, 0) == 0; }

}  // namespace

void validate_density(int density) {
  if (density == 0) return;
  if (std::find(kDensities.begin(), kDensities.end(), density) != kDensities.end()) return;
  throw EnvError("traffic density " + std::to_string(density) +
                 " is not allowed; use 5, 10 or 20 vehicles within 150 m (or 0 for no traffic)");
}

int pretrain_density(std::uint64_t seed, std::int64_t env_step, std::int64_t period_steps) {
  INDRIVE_CHECK(period_steps > 0) << "density period must be positive";
  // One mixing step (splitmix64) per period keeps the choice independent of the step order.
  std::uint64_t z =
      seed + 0x9E3779B97F4A7C15ull * static_cast<std::uint64_t>(env_step / period_steps + 1);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  z ^= z >> 31;
  return kDensities[z % kDensities.size()];
}

TrafficManager::TrafficManager(SumoConnection& sumo, const RoadNetwork& net,
                               std::span<const SpawnPoint> spawns, const TrafficConfig& config)
    : sumo_(&sumo), net_(&net), spawns_(spawns), config_(config) {
  for (const Edge& edge : net.edges()) {
    if (!edge.internal) destinations_.push_back(edge.id);
  }
}

bool TrafficManager::spawnable(const Pose2& ego, const Pose2& spot) const {
  const double dx = spot.x_m - ego.x_m;
  const double dy = spot.y_m - ego.y_m;
  const double dist = std::hypot(dx, dy);
  if (dist > config_.radius_m || dist < config_.min_ego_gap_m) return false;
  // Out of immediate view: not close ahead inside the camera cone.
  const double ahead = dx * std::cos(ego.yaw_rad) + dy * std::sin(ego.yaw_rad);
  if (dist < config_.hidden_ahead_m && ahead > 0.0) {
    const double angle = std::acos(std::clamp(ahead / dist, -1.0, 1.0));
    if (angle < config_.view_half_angle_deg * std::numbers::pi / 180.0) return false;
  }
  return true;
}

void TrafficManager::reset(int density, std::uint64_t seed, const Pose2& ego) {
  validate_density(density);
  density_ = density;
  next_id_ = 0;
  pending_ = 0;
  rng_.seed(seed);
  if (density_ > 0) {
    const int added = spawn(ego, {}, density_);
    if (added < density_) {
      INDRIVE_LOG(kWarn, "traffic")
          << "only " << added << " of " << density_ << " vehicles fit around the ego at reset";
    }
  }
}

int TrafficManager::count_near(const Pose2& ego, std::span<const VehicleState> vehicles) const {
  int count = 0;
  for (const VehicleState& v : vehicles) {
    if (is_traffic(v.id) && distance(v.pose, ego) <= config_.radius_m) ++count;
  }
  return count;
}

void TrafficManager::update(const Pose2& ego, std::span<const VehicleState> vehicles) {
  if (density_ == 0) return;
  int near = 0;
  int traffic_seen = 0;
  for (const VehicleState& v : vehicles) {
    if (!is_traffic(v.id)) continue;
    ++traffic_seen;
    const double d = distance(v.pose, ego);
    if (d > config_.remove_radius_m) {
      sumo_->remove_vehicle(v.id);
    } else if (d <= config_.radius_m) {
      ++near;
    }
  }
  // Vehicles waiting for a free insertion spot count as present, or they would pile up.
  pending_ = sumo_->pending_count();
  const int missing = density_ - near - pending_;
  if (missing > 0) spawn(ego, vehicles, std::min(missing, config_.max_spawns_per_step));
}

int TrafficManager::spawn(const Pose2& ego, std::span<const VehicleState> vehicles, int count) {
  if (spawns_.empty() || destinations_.empty()) return 0;
  just_spawned_.clear();
  int added = 0;
  // Random candidates until enough are placed; bounded so a crowded map cannot loop forever.
  const int attempts = 40 * count;
  for (int attempt = 0; attempt < attempts && added < count; ++attempt) {
    const SpawnPoint& spot = spawns_[draw_index(rng_, spawns_.size())];
    if (!spawnable(ego, spot.pose)) continue;
    auto too_close = [&](const VehicleState& v) {
      return distance(v.pose, spot.pose) < config_.min_vehicle_gap_m;
    };
    if (std::any_of(vehicles.begin(), vehicles.end(), too_close) ||
        std::any_of(just_spawned_.begin(), just_spawned_.end(), too_close)) {
      continue;
    }
    const Lane& lane = net_->lane(spot.lane);
    const std::string& from = net_->edge(lane.edge).id;
    const std::string& to = destinations_[draw_index(rng_, destinations_.size())];
    std::vector<std::string> route =
        from == to ? std::vector<std::string>{from} : sumo_->find_route(from, to);
    if (route.empty()) continue;
    const std::string id = std::string(kIdPrefix) + std::to_string(next_id_++);
    // SUMO places a vehicle by its front bumper: half a length ahead of the spot.
    const double front_s = std::min(spot.s_m + 2.4, lane.length_m);
    sumo_->add_vehicle(id, route, kTrafficType, lane.index, front_s, 0.0);
    just_spawned_.push_back(VehicleState{id, spot.pose, 0.0});
    ++added;
  }
  return added;
}

}  // namespace indrive::env
