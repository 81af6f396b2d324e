#include "indrive/actor/eval_policy.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>
#include <limits>
#include <numbers>
#include <optional>
#include <random>

#include "indrive/common/agent/policy.h"
#include "indrive/common/check.h"
#include "indrive/common/checksum.h"
#include "indrive/common/run_dir.h"
#include "indrive/envserver/events.h"
#include "indrive/envserver/follower.h"
#include "indrive/envserver/town.h"

namespace indrive::actor {
namespace {

constexpr std::uint32_t kBlobMagic = 0x504e4e49;  // "INNP", see common/src/nn/serialize.cc
constexpr std::uint32_t kBlobVersion = 1;

// Snapshot file format 1 (see eval_policy.h): magic, version, header length, header text,
// header CRC-32, then the blob.
constexpr char kFileMagic[8] = {'I', 'N', 'D', 'R', 'S', 'N', 'A', 'P'};
constexpr std::size_t kFilePrefix = sizeof(kFileMagic) + 4 + 4;  // magic, version, length
constexpr std::uint32_t kMaxHeaderBytes = 64 * 1024;
constexpr const char* kActorKey = "actor";

std::string join(const std::vector<std::string>& items, const char* separator = ", ") {
  std::string out;
  for (const auto& item : items) {
    if (!out.empty()) out += separator;
    out += item;
  }
  return out;
}

// Reads the little-endian fields of a parameter blob, with bounds checks.
class BlobCursor {
 public:
  explicit BlobCursor(std::span<const std::uint8_t> data) : data_(data) {}
  bool read(void* out, std::size_t n) {
    if (n > data_.size() - pos_) return false;
    std::memcpy(out, data_.data() + pos_, n);
    pos_ += n;
    return true;
  }
  bool skip(std::uint64_t n) {
    if (n > data_.size() - pos_) return false;
    pos_ += static_cast<std::size_t>(n);
    return true;
  }
  bool u32(std::uint32_t& v) { return read(&v, 4); }
  bool i64(std::int64_t& v) { return read(&v, 8); }
  bool str(std::string& s) {
    std::uint32_t n = 0;
    if (!u32(n) || n > data_.size() - pos_) return false;
    s.assign(reinterpret_cast<const char*>(data_.data() + pos_), n);
    pos_ += n;
    return true;
  }

 private:
  std::span<const std::uint8_t> data_;
  std::size_t pos_ = 0;
};

class SnapshotPolicy final : public EpisodePolicy {
 public:
  SnapshotPolicy(const agent::AgentConfig& config, std::span<const std::uint8_t> blob)
      : policy_(config) {
    policy_.load_snapshot(blob);
  }
  void begin(const env::Env&, const EpisodeSpec& spec) override {
    state_ = {};
    policy_.reseed(spec.policy_seed);
  }
  int act(const env::Env&, const env::StepResult& result) override {
    return policy_.act_eval(
        std::span<const std::uint8_t>(result.observation.data, result.observation.total()),
        result.is_first, state_);
  }

 private:
  agent::Policy policy_;
  agent::PolicyState state_;
};

class OraclePolicy final : public EpisodePolicy {
 public:
  explicit OraclePolicy(const OracleOptions& options) : options_(options) {}
  void begin(const env::Env& env, const EpisodeSpec& spec) override {
    if (env.route() == nullptr) {
      throw EvalError("the oracle policy needs a route; episode of town " + spec.town +
                      " has none");
    }
    follower_.emplace(*env.route(), env.config().ego,
                      env::FollowerConfig{.target_speed_mps = options_.target_speed_mps});
    follower_->reset();
    s_m_ = 0.0;
    previous_.clear();
  }
  int act(const env::Env& env, const env::StepResult& result) override {
    const int action = follower_->act(result.ego);
    if (!options_.brake_for_leader) return action;
    const env::Route& route = *env.route();
    const Eigen::Vector2d position(result.ego.pose.x_m, result.ego.pose.y_m);
    s_m_ = route.project(position, s_m_, 20.0).s_m;
    const auto& others = env.traffic_boxes();
    estimate_velocities(others, env.config().ego.dt_s);
    const double ahead_m = options_.min_gap_m + options_.headway_s * result.ego.speed_mps;
    // Inside a junction with a car close behind, the ego is committed: coasting there lets
    // that car, which SUMO may no longer link to the turning ego, run into it.
    const bool committed = options_.clear_junction && env.events().road().in_junction &&
                           follower_behind(env.ego_box(), others, options_.follower_gap_m);
    const bool yield =
        leader_ahead(route, s_m_, others, ahead_m, options_.corridor_m) ||
        (!committed && conflict_ahead(route, env.ego_box(), s_m_, result.ego.speed_mps, others,
                                      velocities_, options_, yaw_rates_));
    previous_.assign(others.begin(), others.end());
    if (!yield) return action;
    // Keep the follower's steering, drop the throttle: coasting is the only brake there is.
    return env::encode_action(action / 3, 0);
  }

 private:
  // Velocity of each box from the nearest box of the previous step (boxes carry no ids; at
  // most 8.3 m/s, a car moves under 1 m per step, so the nearest within 2 m is the same car).
  void estimate_velocities(std::span<const env::Box> others, double dt_s) {
    velocities_.assign(others.size(), Eigen::Vector2d::Zero());
    yaw_rates_.assign(others.size(), 0.0);
    for (std::size_t i = 0; i < others.size(); ++i) {
      const Eigen::Vector2d now(others[i].pose.x_m, others[i].pose.y_m);
      double best = 2.0;
      for (const env::Box& before : previous_) {
        const Eigen::Vector2d then(before.pose.x_m, before.pose.y_m);
        const double distance = (now - then).norm();
        if (distance < best) {
          best = distance;
          velocities_[i] = (now - then) / dt_s;
          yaw_rates_[i] = env::wrap_angle(others[i].pose.yaw_rad - before.pose.yaw_rad) / dt_s;
        }
      }
    }
  }

  OracleOptions options_;
  std::optional<env::WaypointFollower> follower_;
  double s_m_ = 0.0;
  std::vector<env::Box> previous_;
  std::vector<Eigen::Vector2d> velocities_;
  std::vector<double> yaw_rates_;  // rad/s, counter-clockwise positive, one per box
};

class RandomPolicy final : public EpisodePolicy {
 public:
  explicit RandomPolicy(std::uint64_t seed) : seed_(seed) {}
  void begin(const env::Env&, const EpisodeSpec& spec) override {
    rng_.seed(seed_ * 0x9e3779b97f4a7c15ull + spec.policy_seed + 1);
  }
  int act(const env::Env&, const env::StepResult&) override { return pick_(rng_); }

 private:
  std::uint64_t seed_;
  std::mt19937_64 rng_;
  std::uniform_int_distribution<int> pick_{0, env::kNumActions - 1};
};

}  // namespace

PolicySource parse_policy_source(const std::string& text) {
  if (text == "snapshot") return PolicySource::kSnapshot;
  if (text == "oracle") return PolicySource::kOracle;
  if (text == "random") return PolicySource::kRandom;
  throw EvalError("unknown evaluation policy '" + text +
                  "'; use snapshot (a learner's or a file's), oracle (the route follower) or "
                  "random");
}

const char* to_string(PolicySource source) {
  switch (source) {
    case PolicySource::kSnapshot:
      return "snapshot";
    case PolicySource::kOracle:
      return "oracle";
    case PolicySource::kRandom:
      return "random";
  }
  return "snapshot";
}

PolicyHead resolve_head(const std::string& head, const std::string& eval_kind) {
  if (head == "exploration") return PolicyHead::kExploration;
  if (head == "task") return PolicyHead::kTask;
  if (head == "auto") {
    if (eval_kind == "zero_shot") return PolicyHead::kExploration;
    if (eval_kind == "few_shot") return PolicyHead::kTask;
    throw EvalError("evaluation kind '" + eval_kind +
                    "' does not choose a head; use zero_shot or few_shot, or set eval.head");
  }
  throw EvalError("unknown policy head '" + head + "'; use exploration, task or auto");
}

const char* head_group(PolicyHead head) {
  return head == PolicyHead::kExploration ? "expl_actor" : "task_actor";
}

void check_grid_names(const ProtocolGrid& grid) {
  const std::vector<std::string> builtin = env::builtin_towns();
  for (const std::string& town : grid.towns) {
    const bool known = std::find(builtin.begin(), builtin.end(), town) != builtin.end() ||
                       town.starts_with("grid:") || std::filesystem::is_regular_file(town);
    if (!known) {
      throw EvalError("unknown evaluation town '" + town + "'; use a built-in town (" +
                      join(builtin) + "), a path to a .net.xml or .xodr map, or grid:<seed>");
    }
  }
  for (const std::string& route : grid.routes) {
    if (std::find(env::kRouteNames.begin(), env::kRouteNames.end(), route) ==
        env::kRouteNames.end()) {
      std::vector<std::string> names(env::kRouteNames.begin(), env::kRouteNames.end());
      throw EvalError("unknown evaluation route '" + route + "'; every town has " + join(names));
    }
  }
}

std::vector<std::string> snapshot_groups(std::span<const std::uint8_t> blob) {
  if (blob.size() < 16) {
    throw EvalError("snapshot of " + std::to_string(blob.size()) +
                    " bytes is too short to be a parameter blob");
  }
  std::uint32_t stored = 0;
  std::memcpy(&stored, blob.data() + blob.size() - 4, 4);
  if (crc32(blob.data(), blob.size() - 4) != stored) {
    throw EvalError("snapshot checksum mismatch: the file is corrupt or truncated");
  }
  BlobCursor cursor(blob.first(blob.size() - 4));
  std::uint32_t magic = 0, version = 0, count = 0;
  cursor.u32(magic);
  cursor.u32(version);
  if (magic != kBlobMagic) throw EvalError("snapshot is not a parameter blob (bad magic)");
  if (version != kBlobVersion) {
    throw EvalError("snapshot blob version " + std::to_string(version) + ", this build reads " +
                    std::to_string(kBlobVersion));
  }
  std::vector<std::string> names;
  bool ok = cursor.u32(count);
  for (std::uint32_t g = 0; ok && g < count; ++g) {
    std::string name;
    std::uint32_t params = 0;
    ok = cursor.str(name) && cursor.u32(params);
    names.push_back(name);
    for (std::uint32_t p = 0; ok && p < params; ++p) {
      std::string param;
      std::uint32_t rank = 0;
      ok = cursor.str(param) && cursor.u32(rank) && rank <= 8;
      std::uint64_t numel = 1;
      for (std::uint32_t d = 0; ok && d < rank; ++d) {
        std::int64_t dim = 0;
        ok = cursor.i64(dim) && dim >= 0;
        numel *= static_cast<std::uint64_t>(dim);
      }
      ok = ok && cursor.skip(numel * sizeof(float));
    }
  }
  if (!ok) throw EvalError("snapshot parameter blob is malformed (truncated group or parameter)");
  return names;
}

void check_snapshot_head(std::span<const std::uint8_t> blob, PolicyHead head,
                         const std::string& source) {
  std::vector<std::string> groups;
  try {
    groups = snapshot_groups(blob);
  } catch (const EvalError& error) {
    throw EvalError(source + ": " + error.what());
  }
  const std::string wanted = head_group(head);
  if (std::find(groups.begin(), groups.end(), wanted) != groups.end()) return;
  const bool few_shot = head == PolicyHead::kTask;
  throw EvalError(
      source + " holds the groups [" + join(groups) + "] but not " + wanted + ", the " +
      (few_shot ? "task" : "exploration") + " policy head that " +
      (few_shot ? "few-shot" : "zero-shot") + " evaluation runs; " +
      (few_shot ? "evaluate a finetune (or dreamer) snapshot, or use eval.kind=zero_shot / "
                  "eval.head=exploration"
                : "evaluate a pretraining snapshot, or use eval.kind=few_shot / eval.head=task"));
}

const std::vector<std::string>& snapshot_architecture_keys() {
  static const std::vector<std::string> keys = {
      "preset",
      "phase",
      kActorKey,
      "world_model.image",
      "world_model.channels",
      "world_model.cnn_depth",
      "world_model.deter",
      "world_model.units",
      "world_model.stoch",
      "world_model.classes",
      "world_model.head_layers",
      "behavior.units",
      "behavior.layers",
  };
  return keys;
}

bool is_snapshot_size_key(const std::string& key) {
  return key != "preset" && key != "phase" && key != kActorKey &&
         std::find(snapshot_architecture_keys().begin(), snapshot_architecture_keys().end(), key) !=
             snapshot_architecture_keys().end();
}

std::string SnapshotFile::value(const std::string& key) const {
  for (const auto& [name, text] : architecture) {
    if (name == key) return text;
  }
  return "";
}

namespace {

// The agent config's text of an architecture key (the actor key is not an agent key).
std::string config_text(const agent::AgentConfig& config, const std::string& key) {
  for (const auto& [name, text] : agent::config_values(config)) {
    if (name == key) return text;
  }
  INDRIVE_CHECK(false) << "snapshot architecture key '" << key << "' is not an agent key";
  return "";
}

// Parses and checks the header text of a format-1 file; throws EvalError (without the file
// name) when a line or a required key is missing or a value does not parse.
std::vector<std::pair<std::string, std::string>> parse_header(const std::string& text) {
  std::vector<std::pair<std::string, std::string>> pairs;
  std::size_t begin = 0;
  while (begin < text.size()) {
    const std::size_t end = text.find('\n', begin);
    if (end == std::string::npos) throw EvalError("header: its last line lacks a newline");
    const std::string line = text.substr(begin, end - begin);
    begin = end + 1;
    const std::size_t eq = line.find('=');
    if (eq == std::string::npos || eq == 0) {
      throw EvalError("header: line '" + line + "' is not key=value");
    }
    pairs.emplace_back(line.substr(0, eq), line.substr(eq + 1));
  }
  agent::AgentConfig scratch;
  for (const std::string& key : snapshot_architecture_keys()) {
    const auto it = std::find_if(pairs.begin(), pairs.end(),
                                 [&](const auto& pair) { return pair.first == key; });
    if (it == pairs.end()) throw EvalError("header: it lacks the key " + key);
    if (key == kActorKey || key == "preset") {
      if (it->second.empty()) throw EvalError("header: " + key + " is empty");
      continue;
    }
    try {
      agent::set_config_value(scratch, key, it->second);
    } catch (const agent::AgentConfigError& error) {
      throw EvalError(std::string("header: ") + error.what());
    }
    if (is_snapshot_size_key(key) && config_text(scratch, key).starts_with("-")) {
      throw EvalError("header: " + key + "=" + it->second + " is negative");
    }
  }
  return pairs;
}

// The contents of a snapshot file's bytes (either format); throws EvalError without the name.
SnapshotFile parse_snapshot_file(std::vector<std::uint8_t> bytes) {
  SnapshotFile file;
  std::uint32_t first = 0;
  if (bytes.size() >= 4) std::memcpy(&first, bytes.data(), 4);
  if (first == kBlobMagic) {  // format 0: the bare blob
    snapshot_groups(bytes);
    file.blob = std::move(bytes);
    return file;
  }
  if (bytes.size() < sizeof(kFileMagic) ||
      std::memcmp(bytes.data(), kFileMagic, sizeof(kFileMagic)) != 0) {
    throw EvalError(
        "not a snapshot file (it starts with neither the snapshot file magic "
        "INDRSNAP nor a parameter blob's)");
  }
  if (bytes.size() < kFilePrefix + 4) {
    throw EvalError("header is truncated (the file has " + std::to_string(bytes.size()) +
                    " bytes)");
  }
  std::uint32_t version = 0, length = 0;
  std::memcpy(&version, bytes.data() + sizeof(kFileMagic), 4);
  std::memcpy(&length, bytes.data() + sizeof(kFileMagic) + 4, 4);
  if (length > kMaxHeaderBytes || length > bytes.size() - kFilePrefix - 4) {
    throw EvalError("header is truncated or corrupt (its text claims " + std::to_string(length) +
                    " bytes where " + std::to_string(bytes.size() - kFilePrefix - 4) +
                    " are left)");
  }
  std::uint32_t stored = 0;
  std::memcpy(&stored, bytes.data() + kFilePrefix + length, 4);
  if (crc32(bytes.data(), kFilePrefix + length) != stored) {
    throw EvalError("header checksum mismatch: the file is corrupt");
  }
  if (version != kSnapshotFileFormat) {
    throw EvalError("file format version " + std::to_string(version) +
                    ", this build reads versions 0 and " + std::to_string(kSnapshotFileFormat) +
                    "; evaluate it with the build that wrote it or a newer one");
  }
  file.format = version;
  file.architecture =
      parse_header(std::string(reinterpret_cast<const char*>(bytes.data() + kFilePrefix), length));
  file.blob.assign(bytes.begin() + static_cast<std::ptrdiff_t>(kFilePrefix + length + 4),
                   bytes.end());
  const std::vector<std::string> groups = snapshot_groups(file.blob);
  if (groups.empty() || groups.back() != file.value(kActorKey)) {
    throw EvalError("header names the actor " + file.value(kActorKey) + " but the blob holds [" +
                    join(groups) + "]");
  }
  return file;
}

}  // namespace

SnapshotFile read_snapshot_file(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!std::filesystem::is_regular_file(path) || !in) {
    throw EvalError("snapshot file " + path.string() +
                    " does not exist or cannot be read; name a <run>/eval/snapshot-v<N>.params "
                    "file written by an evaluator");
  }
  std::vector<std::uint8_t> bytes((std::istreambuf_iterator<char>(in)),
                                  std::istreambuf_iterator<char>());
  if (bytes.empty()) throw EvalError("snapshot file " + path.string() + " is empty");
  try {
    return parse_snapshot_file(std::move(bytes));
  } catch (const EvalError& error) {
    throw EvalError("snapshot file " + path.string() + ": " + error.what());
  }
}

void write_snapshot_file(const std::filesystem::path& path, std::span<const std::uint8_t> blob,
                         const agent::AgentConfig& architecture) {
  const std::vector<std::string> groups = snapshot_groups(blob);
  const std::string actor = head_group(
      architecture.phase == agent::Phase::kPretrain ? PolicyHead::kExploration : PolicyHead::kTask);
  if (groups.empty() || groups.back() != actor) {
    throw EvalError("snapshot for " + path.string() + " holds [" + join(groups) +
                    "], but its phase " + std::string(agent::to_string(architecture.phase)) +
                    " acts with " + actor);
  }
  std::string header;
  for (const std::string& key : snapshot_architecture_keys()) {
    const std::string text = key == kActorKey ? actor : config_text(architecture, key);
    INDRIVE_CHECK(text.find('\n') == std::string::npos) << key << " holds a newline";
    header += key + "=" + text + "\n";
  }
  std::vector<std::uint8_t> bytes(kFilePrefix);
  std::memcpy(bytes.data(), kFileMagic, sizeof(kFileMagic));
  const std::uint32_t length = static_cast<std::uint32_t>(header.size());
  std::memcpy(bytes.data() + sizeof(kFileMagic), &kSnapshotFileFormat, 4);
  std::memcpy(bytes.data() + sizeof(kFileMagic) + 4, &length, 4);
  bytes.insert(bytes.end(), header.begin(), header.end());
  const std::uint32_t checksum = crc32(bytes.data(), bytes.size());
  bytes.resize(bytes.size() + 4);
  std::memcpy(bytes.data() + bytes.size() - 4, &checksum, 4);
  bytes.insert(bytes.end(), blob.begin(), blob.end());
  atomic_write(path, bytes);
}

std::string adopt_snapshot_architecture(agent::AgentConfig& config, const SnapshotFile& file,
                                        const std::map<std::string, std::string>& chosen,
                                        const std::string& source) {
  if (file.format == 0) return "";
  const auto preset_choice = chosen.find("preset");
  std::vector<std::string> conflicts;
  std::vector<std::string> undo;  // where the conflicting sizes were chosen, each once
  std::vector<std::string> taken;
  std::string file_sizes;
  for (const std::string& key : snapshot_architecture_keys()) {
    if (!is_snapshot_size_key(key)) continue;
    const std::string wanted = file.value(key);
    file_sizes += (file_sizes.empty() ? "" : " ") + key + "=" + wanted;
    const auto choice = chosen.find(key);
    const std::string have = config_text(config, key);
    if (choice == chosen.end() && preset_choice == chosen.end()) {
      if (have != wanted) agent::set_config_value(config, key, wanted);
      taken.push_back(key + "=" + wanted);
      continue;
    }
    if (have == wanted) continue;
    // A size the preset set is undone by not choosing the preset.
    std::string where = choice != chosen.end() ? choice->second : "preset " + config.preset;
    std::string culprit = where;
    if (preset_choice != chosen.end() &&
        (choice == chosen.end() || where.starts_with("preset '"))) {
      culprit = preset_choice->second;
      if (choice == chosen.end()) where = "preset " + config.preset + " from " + culprit;
    }
    conflicts.push_back(key + "=" + have + " (" + where + ") where the file has " + wanted);
    if (!culprit.starts_with("--set")) culprit = "the setting at " + culprit;
    if (std::find(undo.begin(), undo.end(), culprit) == undo.end()) undo.push_back(culprit);
  }
  const std::string file_preset = file.value("preset");
  if (!conflicts.empty()) {
    throw EvalError(source + " was trained with preset " + file_preset + " (" + file_sizes +
                    "), but the configuration sets " + join(conflicts, "; ") +
                    "; the file decides the model's shapes: drop " + join(undo, " and ") +
                    " to take the sizes from the file, or set them to the file's values");
  }
  std::string note = source + ": architecture from the file's header";
  if (preset_choice == chosen.end()) {
    config.preset = file_preset;
    note += ", preset " + file_preset;
  } else {
    note += ", preset " + config.preset + " as configured";
    if (config.preset != file_preset) note += " (the file's is " + file_preset + ")";
  }
  if (!chosen.contains("phase")) {
    config.phase = agent::parse_phase(file.value("phase"));
    note += ", phase " + file.value("phase");
  }
  note += taken.empty() ? ", every size as configured"
                        : ", sizes taken from the file: " + join(taken, " ");
  return note;
}

int route_step_budget(double length_m, double speed_mps, double slack, double dt_s) {
  INDRIVE_CHECK(length_m >= 0.0 && speed_mps > 0.0 && slack > 0.0 && dt_s > 0.0)
      << "route_step_budget(" << length_m << ", " << speed_mps << ", " << slack << ", " << dt_s
      << ")";
  return std::max(1, static_cast<int>(std::ceil(slack * length_m / (speed_mps * dt_s) - 1e-9)));
}

double route_completion(double progress_m, double length_m, std::uint32_t events) {
  if ((events & env::kDestination) != 0) return 1.0;
  if (length_m <= 0.0) return 0.0;
  return std::clamp(progress_m / length_m, 0.0, 1.0);
}

env::EnvConfig protocol_env_config(env::EnvConfig config) {
  config.events.time_limit_steps = std::numeric_limits<int>::max() / 2;
  return config;
}

EpisodeRecord protocol_record(const EpisodeSpec& spec, std::uint32_t events, int steps,
                              double route_completion, double episode_return) {
  const std::uint32_t failures = events & env::kFailureEvents;
  EpisodeRecord record;
  record.town = spec.town;
  record.route = spec.route;
  record.density = spec.density;
  record.traffic_seed = spec.traffic_seed;
  record.spawn_seed = spec.spawn_seed;
  record.episode = spec.episode;
  record.success = (events & env::kDestination) != 0 && failures == 0;
  record.failure_reason = record.success ? "" : env::event_names(failures);
  record.steps = steps;
  record.route_completion = route_completion;
  record.episode_return = episode_return;
  return record;
}

std::unique_ptr<EpisodePolicy> make_snapshot_policy(agent::AgentConfig agent_config,
                                                    std::span<const std::uint8_t> blob,
                                                    PolicyHead head, const std::string& source) {
  check_snapshot_head(blob, head, source);
  // The policy's acting actor follows the phase: pretrain acts with the exploration actor.
  if (head == PolicyHead::kExploration) {
    agent_config.phase = agent::Phase::kPretrain;
  } else if (agent_config.phase == agent::Phase::kPretrain) {
    agent_config.phase = agent::Phase::kFinetune;
  }
  try {
    return std::make_unique<SnapshotPolicy>(agent_config, blob);
  } catch (const std::exception& error) {
    throw EvalError(source + " does not fit the configured model (preset " + agent_config.preset +
                    "): " + error.what() + "; evaluate it with the preset it was trained with");
  }
}

std::unique_ptr<EpisodePolicy> make_oracle_policy(const OracleOptions& options) {
  return std::make_unique<OraclePolicy>(options);
}

bool leader_ahead(const env::Route& route, double ego_s_m, std::span<const env::Box> others,
                  double ahead_m, double corridor_m) {
  for (const env::Box& box : others) {
    const Eigen::Vector2d centre(box.pose.x_m, box.pose.y_m);
    const env::RoutePoint at = route.project(centre, ego_s_m, ahead_m + 5.0);
    double ds = at.s_m - ego_s_m;
    if (route.is_loop()) {
      ds = std::fmod(ds + route.length_m(), route.length_m());
      if (ds > 0.5 * route.length_m()) ds -= route.length_m();
    }
    if (ds > 0.0 && ds <= ahead_m && std::abs(at.lateral_m) <= corridor_m) return true;
  }
  return false;
}

bool conflict_ahead(const env::Route& route, const env::Box& ego, double ego_s_m,
                    double ego_speed_mps, std::span<const env::Box> others,
                    std::span<const Eigen::Vector2d> velocities, const OracleOptions& options,
                    std::span<const double> yaw_rates) {
  INDRIVE_CHECK_EQ(others.size(), velocities.size());
  INDRIVE_CHECK(yaw_rates.empty() || yaw_rates.size() == others.size())
      << yaw_rates.size() << " yaw rates for " << others.size() << " boxes";
  const double cos_yaw = std::cos(ego.pose.yaw_rad);
  const double sin_yaw = std::sin(ego.pose.yaw_rad);
  const double speed = std::max(ego_speed_mps, options.min_plan_speed_mps);
  constexpr double kSampleS = 0.2;
  for (std::size_t i = 0; i < others.size(); ++i) {
    const env::Box& other = others[i];
    // Behind the ego (in its frame): the other car's business, coasting would not help.
    const double forward =
        cos_yaw * (other.pose.x_m - ego.pose.x_m) + sin_yaw * (other.pose.y_m - ego.pose.y_m);
    if (forward < 0.0) continue;
    // Standing cars are the leader test's business; predicting them here only blocks the ego
    // beside cars that wait at a junction for it.
    const double other_speed = velocities[i].norm();
    if (other_speed < 0.5) continue;
    // A turning car keeps its turn rate until it has turned a right angle (the end of any
    // turn at a junction); a straight-line guess misses the car turning into the ego's road.
    const double rate = yaw_rates.empty() ? 0.0
                                          : std::clamp(yaw_rates[i], -options.max_yaw_rate_rps,
                                                       options.max_yaw_rate_rps);
    double heading = std::atan2(velocities[i].y(), velocities[i].x());
    double turned = 0.0;
    env::Box other_then = other;
    for (double t = 0.0; t <= options.horizon_s + 1e-9; t += kSampleS) {
      env::Box ego_then = ego;
      ego_then.pose = route.pose_at(ego_s_m + speed * t);
      ego_then.length_m += 2.0 * options.clearance_m;
      ego_then.width_m += 2.0 * options.clearance_m;
      if (env::boxes_overlap(ego_then, other_then)) return true;
      other_then.pose.x_m += other_speed * std::cos(heading) * kSampleS;
      other_then.pose.y_m += other_speed * std::sin(heading) * kSampleS;
      if (std::abs(turned) < 0.5 * std::numbers::pi) {
        heading += rate * kSampleS;
        turned += rate * kSampleS;
        other_then.pose.yaw_rad += rate * kSampleS;
      }
    }
  }
  return false;
}

bool follower_behind(const env::Box& ego, std::span<const env::Box> others, double gap_m) {
  const Eigen::Vector2d f(std::cos(ego.pose.yaw_rad), std::sin(ego.pose.yaw_rad));
  for (const env::Box& other : others) {
    const Eigen::Vector2d d(other.pose.x_m - ego.pose.x_m, other.pose.y_m - ego.pose.y_m);
    const double forward = f.dot(d);
    const double lateral = f.x() * d.y() - f.y() * d.x();
    // Behind, roughly in line (a turning ego's rear swings across the lane it came from).
    if (forward < 0.0 && -forward <= gap_m && std::abs(lateral) <= 0.5 * ego.width_m + 2.0) {
      return true;
    }
  }
  return false;
}

std::unique_ptr<EpisodePolicy> make_random_policy(std::uint64_t seed) {
  return std::make_unique<RandomPolicy>(seed);
}

}  // namespace indrive::actor
