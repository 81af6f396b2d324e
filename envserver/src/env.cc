#include "indrive/envserver/env.h"

#include <chrono>
#include <cmath>

#include "indrive/basics/check.h"
#include "indrive/basics/log.h"
#include "indrive/envserver/scene_build.h"

namespace indrive::env {
namespace {

constexpr const char* kEgoId = "ego";

class Stopwatch {
 public:
  Stopwatch() : start_(std::chrono::steady_clock::now()) {}
  // Adds the seconds since the last lap to total.
  void lap(double& total) {
    const auto now = std::chrono::steady_clock::now();
    total += std::chrono::duration<double>(now - start_).count();
    start_ = now;
  }

 private:
  std::chrono::steady_clock::time_point start_;
};

}  // namespace

Env::Env(const EnvConfig& config) : config_(config), model_(config.ego) {
  if (std::abs(config_.events.dt_s - config_.ego.dt_s) > 1e-12 ||
      std::abs(config_.sumo.step_length_s - config_.ego.dt_s) > 1e-12) {
    throw EnvError("ego dt, event dt and SUMO step length must agree (all 0.1 s by default)");
  }
  if (!config_.task.empty()) weights_ = reward_weights(config_.task);
  // Traffic cars get the ego's size: one CARLA-like car model for every vehicle.
  config_.sumo.vehicle_length_m = config_.ego.length_m;
  config_.sumo.vehicle_width_m = config_.ego.width_m;
  validate(config_.camera);
  sumo_ = make_sumo_connection(config_.sumo);
  load_town(config_.town);
}

Env::~Env() = default;

void Env::load_town(const std::string& spec) {
  auto town = std::make_unique<Town>(env::load_town(spec, config_.town_options));
  if (town->spawns.empty()) {
    throw EnvError("town '" + spec + "' has no spawn points (no normal lane long enough)");
  }
  scene_ = std::make_shared<const SceneCache>(build_static_scene(town->net));
  camera_ = std::make_unique<SemanticCamera>(config_.camera, scene_);
  events_ = std::make_unique<EventDetector>(town->net, config_.events, config_.ego);
  traffic_ = std::make_unique<TrafficManager>(*sumo_, town->net, town->spawns, config_.traffic);
  tracker_.reset();
  route_ = nullptr;
  town_ = std::move(town);
  INDRIVE_LOG(kInfo, "env") << "town " << spec << ": " << town_->net.lanes().size() << " lanes, "
                            << town_->spawns.size() << " spawn points";
}

StepResult Env::reset(const ResetOptions& options) {
  validate_density(options.density);
  if (!options.town.empty() && options.town != town_->name) load_town(options.town);

  // Route or random spawn.
  route_ = nullptr;
  tracker_.reset();
  Pose2 start;
  std::string start_edge;
  if (!options.route.empty()) {
    route_ = &find_route(town_->routes, options.route);
    tracker_ = std::make_unique<RouteTracker>(*route_);
    tracker_->reset();
    start = route_->start_pose();
    start_edge = town_->net.edge(town_->net.lane(route_->lanes().front()).edge).id;
  } else {
    std::mt19937_64 rng(options.spawn_seed);
    const SpawnPoint& spawn = town_->spawns[rng() % town_->spawns.size()];
    start = spawn.pose;
    start_edge = town_->net.edge(town_->net.lane(spawn.lane).edge).id;
  }

  if (sumo_failed_) restart_sumo();
  try {
    start_episode(start, start_edge, options.traffic_seed, options.density);
  } catch (const SumoError& e) {
    // A SUMO that died between episodes (libtraci) fails here first: one restart, then retry.
    INDRIVE_LOG(kWarn, "env") << "SUMO failed starting an episode on town " << town_->name << ": "
                              << e.what() << "; restarting SUMO";
    ++env_faults_;
    restart_sumo();
    start_episode(start, start_edge, options.traffic_seed, options.density);
  }
  events_->reset(route_);  // off_route only on a route
  step_ = 0;
  running_ = true;
  render();

  StepResult result;
  result.observation = observation_;
  result.is_first = true;
  result.ego = ego_;
  return result;
}

void Env::start_episode(const Pose2& start, const std::string& start_edge, std::uint64_t seed,
                        int density) {
  // A fresh simulation per episode: the same seeds give the same episode.
  sumo_->load(town_->net_file, seed);
  ego_ = EgoState{.pose = start};
  // On a route SUMO gets the ego's path (a loop three laps over, more than any budget lets it
  // drive), so traffic at junctions yields to it as to any vehicle on the major road.
  std::vector<std::string> ego_route;
  if (route_ != nullptr) {
    const int laps = route_->is_loop() ? 3 : 1;
    for (int lap = 0; lap < laps; ++lap) {
      ego_route.insert(ego_route.end(), route_->spec().edges.begin(), route_->spec().edges.end());
    }
  }
  sumo_->add_ego(kEgoId, start_edge, ego_route);
  sumo_->place_ego(kEgoId, ego_.pose, 0.0);
  traffic_->reset(density, seed, ego_.pose);
  sumo_->step();  // inserts the ego and the first traffic
  read_vehicles();
}

void Env::restart_sumo() {
  traffic_.reset();  // it drives the old connection
  sumo_.reset();     // closes it (in libsumo mode also gives back the process's one simulation)
  sumo_ = make_sumo_connection(config_.sumo);
  traffic_ = std::make_unique<TrafficManager>(*sumo_, town_->net, town_->spawns, config_.traffic);
  sumo_failed_ = false;
}

StepResult Env::fault(const SumoError& error) {
  INDRIVE_LOG(kWarn, "env") << "SUMO failed at step " << step_ << " on town " << town_->name
                            << (route_ != nullptr ? " route " + route_->name() : std::string())
                            << ": " << error.what()
                            << "; the episode ends as env_fault and SUMO restarts";
  ++env_faults_;
  sumo_failed_ = true;
  running_ = false;
  StepResult result;
  result.observation = observation_;
  result.step = step_;
  result.ego = ego_;
  result.events = kEnvFault;
  result.is_last = true;
  result.is_terminal = false;
  return result;
}

StepResult Env::step(int action) {
  INDRIVE_CHECK(running_) << "step() before reset() or after the episode ended";
  Stopwatch watch;

  // Ego dynamics, mirrored into SUMO, then the traffic reacts.
  ego_ = model_.step(ego_, decode_action(action));
  ++step_;
  bool sumo_collision = false;
  try {
    sumo_->place_ego(kEgoId, ego_.pose, ego_.speed_mps);
    sumo_->step();
    read_vehicles();
    watch.lap(timing_.sumo_s);
    traffic_->update(ego_.pose, vehicles_);
    watch.lap(timing_.traffic_s);
    for (const SumoCollision& c : sumo_->collisions()) {
      sumo_collision = sumo_collision || c.collider == kEgoId || c.victim == kEgoId;
    }
  } catch (const SumoError& e) {
    return fault(e);
  }

  // Events, route progress, reward.
  RouteStep progress;
  if (tracker_) progress = tracker_->update(ego_.pose);
  StepResult result;
  result.events = events_->update({.ego = ego_,
                                   .others = boxes_,
                                   .sumo_collision = sumo_collision,
                                   .route_finished = progress.finished,
                                   .route_distance_m = progress.distance_to_route_m,
                                   .step = step_});
  if (events_->sumo_only_collision()) {
    INDRIVE_LOG(kDebug, "env") << "step " << step_
                               << ": SUMO reports a collision of the ego without box contact";
  }
  if (weights_ && route_ != nullptr) {
    const Waypoint& next = route_->waypoints()[progress.next_waypoint];
    const double course = ego_.pose.yaw_rad;
    RewardInputs in;
    in.waypoints_passed = progress.waypoints_passed;
    in.velocity_mps = ego_.speed_mps * Eigen::Vector2d(std::cos(course), std::sin(course));
    in.next_waypoint_heading_rad = next.heading_rad;
    in.lateral_offset_m = progress.lateral_m;
    in.lane_width_m = next.lane_width_m;
    in.collision = (result.events & kCollision) != 0;
    in.destination_reached = (result.events & kDestination) != 0;
    result.reward_terms = compute_reward(*weights_, in);
    result.reward = result.reward_terms.total();
  }
  watch.lap(timing_.events_s);

  render();
  watch.lap(timing_.render_s);
  ++timing_.steps;

  result.observation = observation_;
  result.step = step_;
  result.ego = ego_;
  result.route_progress_m = progress.progress_m;
  result.is_last = ends_episode(result.events);
  result.is_terminal = is_terminal(result.events);
  if (result.is_last) {
    running_ = false;
    if (is_failure(result.events)) {
      // Where, so that a failure of a scripted policy on a user's map can be looked up.
      const RoadStatus& road = events_->road();
      INDRIVE_LOG(kInfo, "env") << "episode failed at step " << step_ << ": "
                                << event_names(result.events) << " at (" << ego_.pose.x_m << ", "
                                << ego_.pose.y_m << ") m on lane "
                                << (road.lane >= 0 ? town_->net.lane(road.lane).id : "none")
                                << (road.in_junction ? " (in a junction)" : "") << ", "
                                << progress.distance_to_route_m << " m from the route";
    }
  }
  return result;
}

void Env::read_vehicles() {
  sumo_->vehicles(vehicles_);
  boxes_.clear();
  for (const VehicleState& v : vehicles_) {
    if (v.id == kEgoId) continue;
    boxes_.push_back(Box{SemanticClass::kVehicle, v.pose, v.length_m, v.width_m, 1.5});
  }
}

void Env::render() { camera_->render(ego_.pose, boxes_, observation_); }

}  // namespace indrive::env
