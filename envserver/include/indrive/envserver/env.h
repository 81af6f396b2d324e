// The driving environment: one SUMO simulation, the ego, traffic, the semantic camera, events
// and (in task phases) the reward, stepped at 10 Hz with the 9 discrete actions.
//
//   EnvConfig config;                       // town01, libsumo, 128x128, pretraining
//   Env env(config);
//   StepResult r = env.reset({.route = "straight", .density = 10, .traffic_seed = 1});
//   while (!r.is_last) r = env.step(action);   // r.observation: CV_8UC1 (H, W) class ids
//
// Determinism: the same config and reset options give bitwise-equal observations, because
// every reset reloads SUMO with the traffic seed and all random choices come from the seeds.
#pragma once

#include <cstdint>
#include <memory>
#include <opencv2/core.hpp>
#include <optional>
#include <string>
#include <vector>

#include "indrive/envserver/camera.h"
#include "indrive/envserver/ego.h"
#include "indrive/envserver/events.h"
#include "indrive/envserver/reward.h"
#include "indrive/envserver/routes.h"
#include "indrive/envserver/sumo.h"
#include "indrive/envserver/town.h"
#include "indrive/envserver/traffic.h"

namespace indrive::env {

// Everything fixed for the life of an Env.
struct EnvConfig {
  std::string town = "town01";  // built-in name or a map path (see town.h)
  TownOptions town_options;
  SumoConfig sumo;
  CameraConfig camera;  // width/height: the preset's image size
  EgoParams ego;
  EventConfig events;
  TrafficConfig traffic;
  // Empty: pretraining (no reward computed). Otherwise lane_following or collision_avoidance.
  std::string task;
};

// Choices of one episode.
struct ResetOptions {
  std::string town;   // empty: keep the current town (the config's at first)
  std::string route;  // empty: random spawn point, no route (pretraining)
  int density = 10;   // traffic vehicles within 150 m: 0, 5, 10 or 20
  std::uint64_t traffic_seed = 0;
  std::uint64_t spawn_seed = 0;
};

// What one reset or step returns.
struct StepResult {
  cv::Mat observation;       // CV_8UC1 (H, W) SemanticClass ids, owned by the Env, valid until the
                             // next step (clone to keep)
  std::uint32_t events = 0;  // EventBit bits
  bool is_first = false;
  bool is_last = false;
  bool is_terminal = false;  // is_last and not a truncation
  EgoState ego;
  std::optional<double> reward;  // task phases only; none in pretraining or on reset
  RewardTerms reward_terms;
  int step = 0;  // steps taken in this episode
  double route_progress_m = 0.0;
};

// Wall-clock seconds spent per part since construction, for the benchmark (steady clock: a
// read costs ~0.1 us, where a thread CPU-time read is a system call of several us).
struct EnvTiming {
  double sumo_s = 0.0;     // ego placement, SUMO step, vehicle readout
  double traffic_s = 0.0;  // traffic upkeep: removing far vehicles, spawning new ones
  double render_s = 0.0;   // camera
  double events_s = 0.0;   // events, route tracking, reward
  std::int64_t steps = 0;
};

class Env {
 public:
  // Loads the config's town and connects to SUMO; throws EnvError, MapError, RouteError,
  // SumoError or CameraError with what is wrong.
  explicit Env(const EnvConfig& config);
  ~Env();
  Env(const Env&) = delete;
  Env& operator=(const Env&) = delete;

  // Starts an episode; throws EnvError for a bad density, RouteError for an unknown route.
  StepResult reset(const ResetOptions& options);
  // Applies action in [0, 9) for one step; INDRIVE_CHECKs that an episode is running. A SUMO
  // failure (SumoError: in libtraci mode also a SUMO process that died) ends the episode with
  // kEnvFault alone, logged with the town and SUMO's message; the next reset() starts a new
  // SUMO. A SUMO failure inside reset() restarts SUMO once and retries before it throws.
  StepResult step(int action);

  const Town& town() const { return *town_; }
  const Route* route() const { return route_; }
  // The SceneCache of the town, shared with a bird's-eye view.
  std::shared_ptr<const SceneCache> scene() const { return scene_; }
  // Other vehicles' boxes after the last step (ego excluded).
  const std::vector<Box>& traffic_boxes() const { return boxes_; }
  Box ego_box() const { return model_.box(ego_.pose); }
  const EgoState& ego() const { return ego_; }
  const EventDetector& events() const { return *events_; }
  const EnvTiming& timing() const { return timing_; }
  const EnvConfig& config() const { return config_; }
  int traffic_count() const { return static_cast<int>(boxes_.size()); }
  // Episodes SUMO failed in (kEnvFault) and SUMO restarts since construction.
  int env_faults() const { return env_faults_; }

 private:
  void load_town(const std::string& spec);
  // Starts SUMO for an episode: a fresh simulation, the ego placed and the first traffic in.
  void start_episode(const Pose2& start, const std::string& start_edge, std::uint64_t seed,
                     int density);
  // A new SUMO connection (and the traffic manager that drives it) after a failure.
  void restart_sumo();
  // Ends the running episode after a SUMO failure (see step()).
  StepResult fault(const SumoError& error);
  void read_vehicles();
  void render();

  EnvConfig config_;
  std::unique_ptr<SumoConnection> sumo_;
  std::unique_ptr<Town> town_;
  std::shared_ptr<const SceneCache> scene_;
  std::unique_ptr<SemanticCamera> camera_;
  std::unique_ptr<EventDetector> events_;
  std::unique_ptr<TrafficManager> traffic_;
  std::optional<RewardWeights> weights_;
  EgoModel model_;
  EgoState ego_;
  const Route* route_ = nullptr;
  std::unique_ptr<RouteTracker> tracker_;
  std::vector<VehicleState> vehicles_;
  std::vector<Box> boxes_;
  cv::Mat observation_;
  int step_ = 0;
  bool running_ = false;
  bool sumo_failed_ = false;  // restart SUMO before the next episode
  int env_faults_ = 0;
  EnvTiming timing_;
};

}  // namespace indrive::env
