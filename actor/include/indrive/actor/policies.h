// What drives the car in an evaluation episode: a frozen snapshot of the agent, a scripted
// oracle (the route follower, with the traffic geometry it coasts for), or uniformly random
// actions.
//
//   auto policy = make_oracle_policy({.brake_for_leader = true});
//   policy->begin(env, spec);               // after env.reset()
//   int action = policy->act(env, result);  // every step
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <string>

#include "indrive/actor/eval_protocol.h"
#include "indrive/actor/snapshot_file.h"
#include "indrive/agent/agent_config.h"
#include "indrive/envserver/env.h"

namespace indrive::actor {

// Where the evaluated actions come from.
enum class PolicySource { kSnapshot, kOracle, kRandom };
// Parses "snapshot", "oracle" or "random"; throws EvalError listing them otherwise.
PolicySource parse_policy_source(const std::string& text);
// The name parse_policy_source() reads back.
const char* to_string(PolicySource source);

// One episode's driver.
class EpisodePolicy {
 public:
  virtual ~EpisodePolicy() = default;
  // Starts an episode that env.reset() has just begun with `spec`.
  virtual void begin(const env::Env& env, const EpisodeSpec& spec) = 0;
  // Returns the action in [0, 9) for the latest result (the reset's, then each step's).
  virtual int act(const env::Env& env, const env::StepResult& result) = 0;
};

// The config a policy acting with `head` is built with: the phase follows the head (pretrain
// acts with the exploration actor; the task actor needs finetune or dreamer).
agent::AgentConfig acting_config(agent::AgentConfig agent_config, PolicyHead head);

// The agent's frozen policy on a parameter blob. agent_config gives the sizes; its phase is
// overridden to match `head`. Throws EvalError when the blob lacks the head or does not fit
// the config's architecture (the message names `source` and the preset).
std::unique_ptr<EpisodePolicy> make_snapshot_policy(agent::AgentConfig agent_config,
                                                    std::span<const std::uint8_t> blob,
                                                    PolicyHead head, const std::string& source);

// Tuning of the oracle.
struct OracleOptions {
  double target_speed_mps = 5.0;
  // Coast (throttle 0, the only way to slow down with the 9 actions) while a vehicle is on the
  // route ahead within the stopping distance plus a margin. Off: the follower alone.
  bool brake_for_leader = true;
  double headway_s = 2.0;   // margin grows with speed: this many seconds of travel
  double min_gap_m = 10.0;  // centre-to-centre distance that always triggers coasting
  double corridor_m = 2.2;  // a vehicle this close to the route centre line is "on" it
  // Crossing traffic (a left turn across oncoming cars, a car entering a junction): coast
  // when the ego's path along the route and another car's straight-line path, both grown by
  // `clearance_m`, meet within `horizon_s`. Coasting from 5 m/s takes about 5 s and 9 m.
  double horizon_s = 4.0;
  double clearance_m = 0.6;
  double min_plan_speed_mps = 3.0;  // the ego's path assumes at least this speed (it speeds up)
  // Inside a junction with a car close behind (`follower_gap_m`, centre to centre), ignore
  // crossing traffic (the leader test still applies) and clear the junction: SUMO stops
  // linking that car to the ego once the ego is on its turning link, so it would run into it.
  bool clear_junction = true;
  double follower_gap_m = 15.0;
  double max_yaw_rate_rps = 1.0;  // measured turn rates are clamped to this (noise guard)
};
// The route follower (envserver WaypointFollower) driving the episode's route with the 9
// discrete actions, optionally coasting behind a leading vehicle.
std::unique_ptr<EpisodePolicy> make_oracle_policy(const OracleOptions& options);
// True when a vehicle (box) lies on `route` ahead of arc length ego_s_m, within `ahead_m`
// along it and `corridor_m` of its centre line: the oracle's braking test.
bool leader_ahead(const env::Route& route, double ego_s_m, std::span<const env::Box> others,
                  double ahead_m, double corridor_m);

// True when `ego` (a box of the ego's size) driven along `route` from arc length ego_s_m at
// max(speed, min_plan_speed_mps) meets one of `others` moving straight at its velocity
// (velocities[i] in m/s, world frame, one per box) within options.horizon_s, both boxes grown
// by options.clearance_m. Vehicles behind the ego are left out: they must mind the ego.
// yaw_rates (rad/s, one per box, or empty for straight lines) bend each car's path: a car
// turning into the ego's road is predicted along its turn, up to a right angle.
bool conflict_ahead(const env::Route& route, const env::Box& ego, double ego_s_m,
                    double ego_speed_mps, std::span<const env::Box> others,
                    std::span<const Eigen::Vector2d> velocities, const OracleOptions& options,
                    std::span<const double> yaw_rates = {});

// True when one of `others` is behind `ego` within gap_m along its heading and about in line
// with it (a car following the ego).
bool follower_behind(const env::Box& ego, std::span<const env::Box> others, double gap_m);

// Uniform actions; the episode's policy seed (with `seed`) makes each episode reproducible.
std::unique_ptr<EpisodePolicy> make_random_policy(std::uint64_t seed);

}  // namespace indrive::actor
