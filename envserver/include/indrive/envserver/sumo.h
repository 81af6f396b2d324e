// The connection to a SUMO simulation, behind one interface with two implementations:
// - libsumo: SUMO runs inside this process (fast; one simulation per process, a SUMO limit).
// - libtraci: SUMO runs as a `sumo` subprocess and is driven over TCP (any number per process).
// Both libraries have the same API, so both implementations share one source.
//
//   SumoConfig config;                       // mode libsumo, step 0.1 s
//   auto sumo = make_sumo_connection(config);
//   sumo->load("town01.net.xml", /*seed=*/7);
//   sumo->add_vehicle("car0", {"e1", "e2"}, kTrafficType, 0, 10.0, 0.0);
//   sumo->step();
//   sumo->vehicles(states);
//
// World frame: SUMO network coordinates, metres, x east, y north; yaw in radians
// counter-clockwise from +x. Positions here are footprint centres (SUMO itself uses the front
// bumper; the conversion happens inside the connection).
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "indrive/envserver/scene.h"

namespace indrive::env {

// SUMO could not be started, loaded, or refused a command. The message names what failed.
class SumoError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// How SUMO is reached.
enum class SumoMode { kLibsumo, kLibtraci };

// Parses "libsumo" or "libtraci"; throws SumoError naming the accepted values otherwise.
SumoMode parse_sumo_mode(std::string_view text);

// Vehicle types the connection defines after every load().
inline constexpr std::string_view kEgoType = "indrive_ego";
inline constexpr std::string_view kTrafficType = "indrive_car";

// How the simulation runs. Defaults suit RL: 10 Hz, fixed seed, no teleporting, junction
// collision checks, collisions only reported (the environment decides what they mean).
struct SumoConfig {
  SumoMode mode = SumoMode::kLibsumo;
  double step_length_s = 0.1;
  // The sumo executable for libtraci mode; empty means the one found at build time.
  std::filesystem::path sumo_binary;
  double traffic_max_speed_mps = 8.33;  // 30 km/h, urban traffic as in the CARLA towns
  double vehicle_length_m = 4.8;        // ego and traffic, a CARLA-like car
  double vehicle_width_m = 2.1;
  // Sublane width (m) of SUMO's lateral model; 0 turns it off. With it, traffic behind a
  // turning ego keeps treating it as its leader while the ego still overlaps its path.
  double lateral_resolution_m = 0.8;
  std::vector<std::string> extra_args;  // appended to the command line as given
};

// One vehicle as the environment sees it.
struct VehicleState {
  std::string id;
  Pose2 pose;  // footprint centre and heading
  double speed_mps = 0.0;
  double length_m = 4.8;
  double width_m = 2.1;
};

// A lane's centre line and width, as SUMO has it after loading the network.
struct LaneGeometry {
  std::string id;
  std::string edge_id;
  bool internal = false;  // a lane inside a junction (SUMO ids starting with ':')
  double width_m = 3.2;
  std::vector<Eigen::Vector2d> shape;  // centre line in driving direction, >= 2 points
};

// A junction's outline.
struct JunctionGeometry {
  std::string id;
  std::vector<Eigen::Vector2d> shape;  // closed implicitly; may be empty for dead ends
};

// A collision SUMO reported during the last step.
struct SumoCollision {
  std::string collider;
  std::string victim;
};

// A running SUMO simulation. Not thread-safe; one owner drives it.
class SumoConnection {
 public:
  virtual ~SumoConnection() = default;

  // (Re)starts the simulation on a network with a seed; all vehicles are gone afterwards and
  // the time is 0. Throws SumoError for a missing or malformed network.
  virtual void load(const std::filesystem::path& net_file, std::uint64_t seed) = 0;
  // Advances the simulation by one step (step_length_s).
  virtual void step() = 0;
  // Simulation time in seconds.
  virtual double time_s() = 0;

  // Lanes (normal and internal) and junctions of the loaded network.
  virtual std::vector<LaneGeometry> lanes() = 0;
  virtual std::vector<JunctionGeometry> junctions() = 0;
  // Fastest route between two normal edges as a list of edge ids; empty if none exists.
  virtual std::vector<std::string> find_route(const std::string& from_edge,
                                              const std::string& to_edge) = 0;

  // Inserts a vehicle of type_id on the first edge of route at lane_index, pos_m from the
  // lane start, with an initial speed. SUMO may delay insertion while the spot is blocked.
  virtual void add_vehicle(const std::string& id, const std::vector<std::string>& route,
                           std::string_view type_id, int lane_index, double pos_m,
                           double speed_mps) = 0;
  // Removes a vehicle (inserted or still pending); unknown ids are ignored.
  virtual void remove_vehicle(const std::string& id) = 0;
  // Adds the externally driven ego: SUMO never moves it, only place_ego() does. route_edges,
  // when given, is the path the ego is going to drive (starting on edge_id): SUMO then
  // registers the ego's approach at the junctions ahead, so traffic on minor roads yields to
  // it; with only its start edge the ego is invisible to SUMO's right-of-way.
  virtual void add_ego(const std::string& id, const std::string& edge_id,
                       const std::vector<std::string>& route_edges = {}) = 0;
  // Puts the ego at a pose anywhere (free placement, no route constraint) for the next step,
  // so that SUMO traffic sees it and reacts to it.
  virtual void place_ego(const std::string& id, const Pose2& pose, double speed_mps) = 0;

  // Every vehicle in the network after the last step (ids sorted), the ego included.
  virtual void vehicles(std::vector<VehicleState>& out) = 0;
  // Number of vehicles added but not yet inserted (blocked insertion spots).
  virtual int pending_count() = 0;
  // Collisions SUMO detected in the last step.
  virtual std::vector<SumoCollision> collisions() = 0;
  // Ids of vehicles that left the network in the last step (arrived at their destination).
  virtual std::vector<std::string> arrived() = 0;

  virtual const SumoConfig& config() const = 0;
};

// Builds a connection in the configured mode; nothing runs until load(). Throws SumoError if
// the mode cannot be used (libsumo already in use in this process, sumo binary missing).
std::unique_ptr<SumoConnection> make_sumo_connection(const SumoConfig& config);

// The SUMO command line (without the binary) for a network and seed.
std::vector<std::string> sumo_arguments(const SumoConfig& config,
                                        const std::filesystem::path& net_file, std::uint64_t seed);

}  // namespace indrive::env
