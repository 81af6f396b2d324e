// SUMO traffic around the ego, kept at a configured density.
//
// The density is the number of traffic vehicles within radius_m (150 m) of the ego: 5, 10 or
// 20, as in the paper. Missing vehicles are spawned at spawn points inside the radius but out
// of the ego's immediate view (not within hidden_ahead_m ahead inside the camera cone) and not
// next to another vehicle; each drives a random route to a random destination edge, where
// SUMO removes it. Vehicles beyond remove_radius_m are removed. All choices come from the
// traffic seed, so the same seeds give the same traffic.
//
//   TrafficManager traffic(sumo, net, spawns, TrafficConfig{});
//   traffic.reset(/*density=*/10, /*seed=*/3, ego_pose);
//   ... each step, after sumo.step():  traffic.update(ego_pose, vehicles);
#pragma once

#include <array>
#include <cstdint>
#include <random>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

#include "indrive/envserver/net.h"
#include "indrive/envserver/scene_build.h"
#include "indrive/envserver/sumo.h"

namespace indrive::env {

// A setting of the environment that cannot work (bad density, unknown route, ...).
class EnvError : public std::invalid_argument {
 public:
  using std::invalid_argument::invalid_argument;
};

// The densities the paper uses.
inline constexpr std::array<int, 3> kDensities = {5, 10, 20};

// Throws EnvError unless density is 0 (no traffic) or one of kDensities.
void validate_density(int density);

// The density of pretraining step env_step: resampled from kDensities every period_steps,
// deterministic in (seed, env_step / period_steps).
int pretrain_density(std::uint64_t seed, std::int64_t env_step, std::int64_t period_steps = 10000);

// Where and how traffic is spawned.
struct TrafficConfig {
  double radius_m = 150.0;            // density counts vehicles within this distance
  double remove_radius_m = 180.0;     // vehicles beyond are removed (hysteresis over radius_m)
  double hidden_ahead_m = 30.0;       // no spawns closer than this ahead inside the view cone
  double view_half_angle_deg = 50.0;  // camera cone half angle (90 deg FOV plus a margin)
  double min_ego_gap_m = 12.0;        // no spawns this close to the ego in any direction
  double min_vehicle_gap_m = 10.0;    // no spawns this close to another vehicle
  int max_spawns_per_step = 3;        // after reset; the reset itself fills up at once
};

// Keeps the traffic density around the ego.
class TrafficManager {
 public:
  // sumo, net and spawns must outlive the manager.
  TrafficManager(SumoConnection& sumo, const RoadNetwork& net, std::span<const SpawnPoint> spawns,
                 const TrafficConfig& config = {});

  // Starts an episode: density vehicles (0 for none) spawned around the ego at once, using
  // the traffic seed. Call after SumoConnection::load() and before the first step.
  void reset(int density, std::uint64_t seed, const Pose2& ego);
  // Removes far vehicles and spawns up to max_spawns_per_step new ones. vehicles are the
  // current vehicles (the ego may be among them and is skipped by id).
  void update(const Pose2& ego, std::span<const VehicleState> vehicles);

  // Traffic vehicles within radius_m of the ego among vehicles (the ego excluded).
  int count_near(const Pose2& ego, std::span<const VehicleState> vehicles) const;
  int density() const { return density_; }
  // Vehicles spawned since reset.
  int spawned() const { return next_id_; }
  // True when a point is a valid spawn spot for the ego pose (radius, view cone, ego gap).
  bool spawnable(const Pose2& ego, const Pose2& spot) const;
  // The id prefix of traffic vehicles.
  static constexpr const char* kIdPrefix = "traffic";

 private:
  // Adds up to `count` vehicles; returns how many were added.
  int spawn(const Pose2& ego, std::span<const VehicleState> vehicles, int count);

  SumoConnection* sumo_;
  const RoadNetwork* net_;
  std::span<const SpawnPoint> spawns_;
  TrafficConfig config_;
  std::vector<std::string> destinations_;  // normal edge ids
  int density_ = 0;
  int next_id_ = 0;
  int pending_ = 0;  // spawned but not yet seen in the network
  std::mt19937_64 rng_;
  std::vector<VehicleState> just_spawned_;  // spots taken in this update, for the gap check
};

}  // namespace indrive::env
