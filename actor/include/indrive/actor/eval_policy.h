// What drives the car in an evaluation episode: a frozen snapshot of the agent, a scripted
// oracle (the route follower), or uniformly random actions; plus the checks of the evaluator's
// inputs (grid names, snapshot heads) and the per-route step budget.
//
// Snapshot files: a snapshot on disk is a small architecture header followed by the parameter
// blob of Agent::snapshot() (the bytes a PolicySnapshot carries in `params`: world model group,
// then one actor group, "expl_actor" in pretraining or "task_actor" in finetune/dreamer, with a
// trailing CRC-32). The DDS evaluator saves the snapshot it evaluates as
// <run>/eval/snapshot-v<version>.params, so it can be evaluated again later without a learner
// and without naming its preset: `indrive-actor --evaluate --snapshot FILE`.
//
// File format 1 (little-endian; written by write_snapshot_file, read by read_snapshot_file):
//   "INDRSNAP"   8 bytes, the file magic
//   u32          file format version (kSnapshotFileFormat)
//   u32          N, length of the header text (at most 64 KiB)
//   N bytes      header text, one "key=value\n" line per snapshot_architecture_keys() entry:
//                preset, phase, actor (the blob's actor group), then the size keys
//   u32          CRC-32 of everything above
//   ...          the parameter blob, with its own trailing CRC-32
// Format 0, written before the header existed, is the bare blob (it starts with the blob magic
// "INNP"); it still loads, and its preset must then be given (--set preset=NAME).
//
//   auto policy = make_oracle_policy({.brake_for_leader = true});
//   policy->begin(env, spec);               // after env.reset()
//   int action = policy->act(env, result);  // every step
#pragma once

#include <cstdint>
#include <filesystem>
#include <map>
#include <memory>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

#include "indrive/actor/protocol.h"
#include "indrive/common/agent/config.h"
#include "indrive/common/episode_csv.h"
#include "indrive/envserver/env.h"

namespace indrive::actor {

// A bad evaluator input (unknown town, route, policy or head; unreadable snapshot file; a
// snapshot without the head asked for). The message names the value and what is allowed.
class EvalError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Where the evaluated actions come from.
enum class PolicySource { kSnapshot, kOracle, kRandom };
// Parses "snapshot", "oracle" or "random"; throws EvalError listing them otherwise.
PolicySource parse_policy_source(const std::string& text);
// The name parse_policy_source() reads back.
const char* to_string(PolicySource source);

// Which actor of a snapshot acts: the exploration actor (zero-shot) or the task actor
// (few-shot).
enum class PolicyHead { kExploration, kTask };
// Resolves eval.head: "exploration", "task", or "auto" (exploration for eval_kind zero_shot,
// task for few_shot). Throws EvalError for anything else.
PolicyHead resolve_head(const std::string& head, const std::string& eval_kind);
// The parameter-group name of a head's actor ("expl_actor" or "task_actor").
const char* head_group(PolicyHead head);

// Throws EvalError unless every town is a built-in name, an existing map file or grid:<seed>,
// and every route is one of the four route names; the message lists the allowed values.
void check_grid_names(const ProtocolGrid& grid);

// Names of the parameter groups in a parameter blob, in order (no values are copied). Throws
// EvalError when the blob is not one (bad magic, truncated, checksum mismatch).
std::vector<std::string> snapshot_groups(std::span<const std::uint8_t> blob);
// Throws EvalError naming `source`, the groups the snapshot holds and what to do, when the
// blob has no actor group for `head`.
void check_snapshot_head(std::span<const std::uint8_t> blob, PolicyHead head,
                         const std::string& source);
// The version of the snapshot file format that write_snapshot_file writes (0: bare blob).
inline constexpr std::uint32_t kSnapshotFileFormat = 1;

// The agent keys a snapshot file's header records, in order: "preset", "phase", "actor" (the
// actor group, not an agent key), then every size that decides the shapes of the world model
// and actor (world_model.image ... world_model.head_layers, behavior.units, behavior.layers).
const std::vector<std::string>& snapshot_architecture_keys();
// True for the keys of snapshot_architecture_keys() that are sizes (shape-deciding numbers).
bool is_snapshot_size_key(const std::string& key);

// A snapshot file's contents.
struct SnapshotFile {
  std::uint32_t format = 0;        // 0: a bare blob from before the header; else its version
  std::vector<std::uint8_t> blob;  // the parameter blob
  // The header's key=value pairs, in file order (empty for format 0).
  std::vector<std::pair<std::string, std::string>> architecture;

  // The header's value of `key` ("" when absent).
  std::string value(const std::string& key) const;
};

// Reads a snapshot file of either format; throws EvalError naming the file when it is missing,
// empty, of an unknown format, or its header or blob is truncated, corrupt or incomplete.
SnapshotFile read_snapshot_file(const std::filesystem::path& path);
// Writes a snapshot file (format kSnapshotFileFormat) atomically: the header records the
// preset, phase and sizes of `architecture` (the agent config the blob was made with) and the
// blob's actor group. Throws EvalError when the blob is not a parameter blob or its actor group
// is not the one of the config's phase.
void write_snapshot_file(const std::filesystem::path& path, std::span<const std::uint8_t> blob,
                         const agent::AgentConfig& architecture);

// Sizes `config` by a snapshot file's header, as evaluating that file needs: every size key,
// the preset name and the phase that `chosen` does not name are taken from the header.
// `chosen`: the agent keys the configuration chose explicitly, each with where ("preset" ->
// "--set preset=cpu", "world_model.deter" -> "preset 'cpu'"; ServiceConfig::agent_choices());
// a chosen "preset" counts as choosing every size. Throws EvalError naming `source`, each
// chosen size that differs from the file (both values and where it was chosen) and what to
// do. Returns a line for the log saying what was taken from the file; for a format-0 file
// (no header) it changes nothing and returns "".
std::string adopt_snapshot_architecture(agent::AgentConfig& config, const SnapshotFile& file,
                                        const std::map<std::string, std::string>& chosen,
                                        const std::string& source);

// Step budget of a route: ceil(slack * length_m / (speed_mps * dt_s)). With the defaults
// (3 m/s, the slower task speed, and 1.5x slack at 10 Hz) that is 5 steps per metre: 3,245 steps
// for town01's longest loop (649 m), where a fixed 1,000 steps (100 s) covers 300-600 m at
// 3-6 m/s, less than one lap.
int route_step_budget(double length_m, double speed_mps = 3.0, double slack = 1.5,
                      double dt_s = 0.1);
// The fraction of the route an episode drove, in [0, 1]: progress_m / length_m (the route's
// length, set back from its last junction on a point-to-point route), and 1 when the
// destination event fired (within kDestinationRadiusM of the terminal waypoint, or a lap).
double route_completion(double progress_m, double length_m, std::uint32_t events);
// The env config for protocol episodes: the route's step budget ends them, so the training
// time limit (env.time_limit_steps) is lifted out of its way.
env::EnvConfig protocol_env_config(env::EnvConfig config);

// The protocol's verdict on one episode of `spec`, as a CSV row without the run-level fields
// (run id, method, eval kind, task, seeds of training, policy version): success means the
// destination event with no failure event; otherwise the failure events name the reason.
// `events`: EventBit bits of the last step (kTimeLimit included when the budget ran out).
EpisodeRecord protocol_record(const EpisodeSpec& spec, std::uint32_t events, int steps,
                              double route_completion, double episode_return);

// One episode's driver.
class EpisodePolicy {
 public:
  virtual ~EpisodePolicy() = default;
  // Starts an episode that env.reset() has just begun with `spec`.
  virtual void begin(const env::Env& env, const EpisodeSpec& spec) = 0;
  // Returns the action in [0, 9) for the latest result (the reset's, then each step's).
  virtual int act(const env::Env& env, const env::StepResult& result) = 0;
};

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
