#include "indrive/service/run_config.h"

#include <charconv>
#include <cmath>
#include <cstdio>
#include <set>

#include "indrive/agent/agent.h"
#include "indrive/agent/precision_choice.h"
#include "indrive/basics/data_path.h"
#include "indrive/basics/log.h"
#include "indrive/dds/participant.h"
#include "indrive/dds/security.h"

namespace indrive::service {
namespace {

constexpr const char* kAgentPrefix = "agent.";
constexpr const char* kDefaultPreset = "cpu";

// Agent keys whose text is not a number, with the values they may take.
bool is_text_agent_key(const std::string& key) {
  static const std::set<std::string> text_keys = {"preset",
                                                  "phase",
                                                  "task",
                                                  "eval_sample",
                                                  "intrinsic.method",
                                                  "intrinsic.disag_reward",
                                                  "precision",
                                                  "backward_parts",
                                                  "finetune_cont",
                                                  "finetune_world_model"};
  return text_keys.contains(key);
}

// Text of a double that the agent's integer and float parsers both read back.
std::string number_text(double value) {
  if (std::floor(value) == value && std::fabs(value) < 9.0e15) {
    return std::to_string(static_cast<long long>(value));
  }
  char buffer[64];
  std::snprintf(buffer, sizeof(buffer), "%.9g", value);
  return buffer;
}

// The agent's keys (agent.*) and the presets that set them.
void declare_agent_keys(config::Schema& schema) {
  // The agent's keys, mirrored under agent.* with the default preset's values; the agent's own
  // parser checks each value when the config is turned into an AgentConfig.
  const agent::AgentConfig defaults = agent::preset(kDefaultPreset);
  for (const auto& [key, text] : agent::config_values(defaults)) {
    if (key == "preset") continue;  // the config's top-level preset names it
    const std::string name = kAgentPrefix + key;
    if (key == "phase") {
      schema.add_choice(name, text, {"pretrain", "finetune", "dreamer"}, "training phase");
    } else if (key == "task") {
      schema.add_choice(name, text, {"lane_following", "collision_avoidance"},
                        "task of the finetune and dreamer phases");
    } else if (key == "intrinsic.method") {
      schema.add_choice(name, text, {"disag", "icm", "rnd"}, "intrinsic reward of pretraining");
    } else if (key == "intrinsic.disag_reward") {
      schema.add_choice(name, text, {"variance", "std"}, "how disagreement becomes a reward");
    } else if (key == "precision") {
      schema.add_choice(name, text, {"auto", "fp32", "bf16"},
                        "operands of the learner's matrix products: auto is bf16 where the CPU "
                        "multiplies it natively (AMX, AVX512_BF16), else fp32");
    } else if (key == "eval_sample") {
      schema.add_bool(name, text == "true", "evaluation samples actions instead of the mode");
    } else if (key == "backward_parts") {
      schema.add_bool(name, text == "true",
                      "the learner's backward pass runs its independent parts (world model, "
                      "intrinsic module, actor-critic) side by side, one thread each, instead of "
                      "one after another with each op split over the threads (the tiny preset's "
                      "default, measured faster there; slower on cpu)");
    } else if (key == "finetune_cont") {
      schema.add_bool(name, text == "true",
                      "few-shot also trains the world model's continuation head (stop-gradient "
                      "features), so imagination learns where task episodes end; the paper keeps "
                      "the world model frozen (an ablation, docs/decisions.md)");
    } else if (key == "finetune_world_model") {
      schema.add_bool(name, text == "true",
                      "few-shot also trains the whole world model on the task's replay, from the "
                      "pretrained weights; the paper keeps it frozen (an ablation, "
                      "docs/decisions.md; excludes finetune_cont)");
    } else {
      double value = 0.0;
      std::from_chars(text.data(), text.data() + text.size(), value);
      schema.add_float(name, value,
                       "agent " + key + " (see common/agent/include/indrive/agent/agent_config.h)");
    }
  }
  for (const char* name : {"tiny", "cpu", "small"}) {
    std::vector<std::pair<std::string, std::string>> overrides;
    for (const auto& [key, text] : agent::config_values(agent::preset(name))) {
      // Text keys are the same in every preset, except the backward's schedule.
      if (key == "preset" || (is_text_agent_key(key) && key != "backward_parts")) continue;
      overrides.emplace_back(kAgentPrefix + key, text);
    }
    schema.add_preset(name, std::move(overrides),
                      std::string("agent sizes of the ") + name + " preset (ARCHITECTURE.md 6)");
  }
}

// run.* and env.*: the seed, the budget and the environment.
void declare_run_and_env_keys(config::Schema& schema) {
  schema.add_int("run.seed", 0, "seed of spawns, traffic and random actions", 0)
      .add_int("run.budget_env_steps", 0,
               "the learner stops after this many env steps (0: no limit)", 0);
  schema.add_string("env.town", "town01", "training town (built-in name or map path)")
      .add_choice("env.sumo_mode", "libsumo", {"libsumo", "libtraci"},
                  "SUMO in-process (libsumo) or as a subprocess (libtraci)")
      .add_number_list("env.densities", {5, 10, 20}, "traffic densities to draw from", 0, 20)
      .add_int("env.density_period_steps", 10000, "env steps between density draws", 1)
      .add_int("env.time_limit_steps", 1000, "episode length limit in steps", 1)
      .add_string("env.route", "", "route of the task phases; empty: random spawns without a route")
      .add_choice("env.route_set", "right", {"right", "left"},
                  "built-in towns' routes: right (one layout rule follows straight and "
                  "right_loop) or left, the mirror design (straight and left_loop)")
      .add_float("env.coverage_segment_m", 10.0,
                 "length of the lane pieces the exploration coverage counts", 0.5);
}

// actor.* and local.*: what training actors and indrive-train-local do.
void declare_actor_keys(config::Schema& schema) {
  schema.add_int("actor.chunk_length", 64, "steps per TrajectoryChunk (L)", 1, 4096)
      .add_float("actor.heartbeat_s", 1.0, "seconds between heartbeats", 0.05)
      .add_float("actor.request_after_s", 2.0,
                 "seconds an announced snapshot may be missing before it is re-requested", 0.1)
      .add_float("actor.rejoin_after_s", 20.0,
                 "seconds without word of the learner (allowance or heartbeat) after which a "
                 "waiting actor or evaluator replaces its DDS participant; over UDP and for "
                 "evaluators only one that never heard the learner (0: never)",
                 0.0)
      .add_float("actor.rejoin_max_s", 160.0,
                 "longest wait between two such replacements: the wait doubles from "
                 "actor.rejoin_after_s for each replacement that heard nothing, and is "
                 "actor.rejoin_after_s again once the learner is heard",
                 0.0)
      .add_float("actor.coverage_period_s", 60.0,
                 "seconds between writes of the actor's coverage/actor-<id>.csv", 1.0);
  schema.add_bool("local.random", false,
                  "indrive-train-local acts randomly throughout and never trains (the "
                  "exploration baseline)");
}

// learner.*: replay ratio, snapshots, logs, checkpoints, the page.
void declare_learner_keys(config::Schema& schema) {
  schema
      .add_float("learner.replay_ratio", 32.0, "replayed steps per env step the learner keeps",
                 0.001)
      .add_bool("learner.async", false, "lift the rate limit (throughput runs)")
      .add_int("learner.allowance_slack", 64, "env steps actors may run ahead of training", 1)
      .add_int("learner.snapshot_every", 10, "updates between PolicySnapshots", 1)
      .add_float("learner.announce_s", 1.0, "seconds between SnapshotAnnounce messages", 0.05)
      .add_float("learner.snapshot_hold_s", 10.0,
                 "a due snapshot waits until every reader has the last one, at most this long "
                 "(a reader gone keeps its match until its DDS lease ends)",
                 0.0)
      .add_float("learner.log_interval_s", 5.0, "seconds between metrics lines", 0.1)
      .add_int("learner.log_every_env_steps", 1000,
               "also a metrics line each time the env steps pass a multiple of this (0: off), so "
               "fast and slow runs have comparable curves",
               0)
      .add_float("learner.checkpoint_minutes", 5.0, "minutes between checkpoints", 0.01)
      .add_int("learner.checkpoint_keep", 3, "checkpoints kept", 1)
      .add_string("learner.init_checkpoint", "",
                  "checkpoint of a pretraining run to start finetuning from")
      .add_float("learner.dashboard_s", 30.0,
                 "seconds between rewrites of the run's page, <run>/index.html, by an `indrive "
                 "dashboard` process the learner (or indrive-train-local) starts beside itself "
                 "(0: none; `indrive launch` sets 0 and writes the page itself)",
                 0.0);
}

// eval.*: the evaluation grid, its protocol, the policies and the probe.
void declare_eval_keys(config::Schema& schema) {
  schema.add_string("eval.towns", "town01,town02", "towns of the evaluation grid, comma-separated")
      .add_string("eval.routes", "all",
                  "routes of the evaluation grid, comma-separated, or all: every town's own "
                  "routes (our towns: straight, right_loop, left_loop, two_turn; the CARLA "
                  "towns: the public InDRiVE code's)")
      .add_choice("eval.protocol", "strict", {"strict", "indrive_code"},
                  "rules that judge an episode: strict (ours: the route's budget, every road "
                  "rule and leaving the route end it) or indrive_code (the public InDRiVE "
                  "code's: 2 m of the end point by any path, a fixed budget; "
                  "docs/evaluation.md)")
      .add_int("eval.indrive_code_budget_steps", 30000,
               "indrive_code: steps before an episode ends unfinished (the code's 30,000)", 1)
      .add_number_list("eval.densities", {5, 10, 20}, "densities of the evaluation grid", 0, 20)
      .add_int("eval.episodes_per_cell", 50, "episodes per town x route x density", 1)
      .add_bool("eval.wait_for_done", true,
                "evaluate the learner's last snapshot (wait until it reports done)")
      .add_float("eval.snapshot_timeout_s", 3600.0, "give up when no snapshot comes in time", 1.0)
      .add_bool("eval.resume", false,
                "go on with an evaluation stopped part-way: the episodes this evaluator's "
                "results file holds for the same policy, kind and protocol are not run again "
                "(the file must hold that evaluation's rows only)")
      .add_float("eval.learner_silence_s", 120.0,
                 "with wait_for_done: evaluate the newest snapshot held, with a warning, once "
                 "the learner has not been heard from for this long (0: wait for it)",
                 0.0)
      .add_choice("eval.kind", "zero_shot", {"zero_shot", "few_shot"},
                  "evaluation kind written to the results")
      .add_choice("eval.policy", "snapshot", {"snapshot", "oracle", "random"},
                  "what drives: a snapshot (learner's or eval.snapshot_file), the route "
                  "follower, or uniform actions")
      .add_string("eval.snapshot_file", "",
                  "snapshot file (parameter blob, <run>/eval/snapshot-v<N>.params) to evaluate "
                  "without DDS; empty: the learner's")
      .add_choice("eval.head", "auto", {"auto", "exploration", "task"},
                  "actor that acts; auto: exploration for zero_shot, task for few_shot")
      .add_bool("eval.oracle_brake", true, "the oracle coasts behind a vehicle ahead on its route")
      .add_float("eval.oracle_speed_mps", 5.0, "target speed of the oracle", 0.5, 6.0)
      .add_float("eval.budget_speed_mps", 3.0,
                 "step budget of an episode: route length at this speed ...", 0.1)
      .add_float("eval.budget_slack", 1.5, "... times this slack", 1.0)
      .add_int("eval.video_episodes", 0,
               "record the first N episodes of every cell to <run>/videos/eval-*.mp4", 0)
      .add_bool("eval.continuous", false,
                "evaluate every eval.every_k-th new snapshot into eval/curve-<id>.csv")
      .add_int("eval.every_k", 1, "snapshot versions between continuous evaluations", 1)
      .add_float("eval.probe_far_m", 14.0,
                 "route probe (indrive-route-probe): states are recorded from this many metres "
                 "before each junction where a route chooses ...",
                 1.0, 100.0)
      .add_float("eval.probe_near_m", 6.0,
                 "... to this many (the oracle steers for a point up to 8 m ahead: nearer, its "
                 "actions show the turn)",
                 0.0, 99.0)
      .add_bool("eval.probe_oracle_brake", false,
                "route probe: the oracle coasts behind leaders and for crossing traffic (off: "
                "its coasting depends on the turn ahead and so tells the exit)");
}

}  // namespace

void declare_service_schema(config::Schema& schema) {
  declare_agent_keys(schema);
  declare_run_and_env_keys(schema);
  declare_actor_keys(schema);
  declare_learner_keys(schema);
  declare_eval_keys(schema);
  dds::declare_config(schema);
}

const config::Schema& service_schema() {
  static const config::Schema schema = [] {
    config::Schema built;
    declare_service_schema(built);
    return built;
  }();
  return schema;
}

ServiceConfig ServiceConfig::resolve(const ServiceOptions& options) {
  if (options.run_dir.empty()) {
    throw config::ConfigError("no run directory: pass --run-dir runs/<run_id>");
  }
  ServiceConfig service(config::Config::resolve(
      service_schema(), {.file = options.config_file, .overrides = options.overrides}));
  service.run_dir_ = options.run_dir;
  service.run_id_ = options.run_dir.lexically_normal().filename().string();
  if (service.run_id_.empty()) service.run_id_ = options.run_dir.parent_path().filename().string();
  if (options.domain_id >= 0) {
    service.config_.set("dds.domain_id", std::to_string(options.domain_id), "--domain");
  }
  service.domain_id_ = service.config_.get<int>("dds.domain_id");
  if (!options.dds_profile.empty()) {
    service.config_.set("dds.profiles_file", options.dds_profile, "--dds-profile");
  }
  service.dds_profile_ = service.config_.get<std::string>("dds.profiles_file");
  if (!options.discovery_server.empty()) {
    service.config_.set("dds.discovery_server", options.discovery_server, "--discovery-server");
  }
  if (!options.dds_security.empty()) {
    service.config_.set("dds.security_dir", options.dds_security, "--dds-security");
  }
  if (service.dds_profile_.empty() && std::getenv(dds::kProfilesEnvVar) == nullptr) {
    // Neither flag, config nor environment names one: use the shipped single-host profile,
    // found under the data roots (installed tree or source tree, see data_path.h).
    service.dds_profile_ = find_data("deploy/dds/single_host.xml").string();
  }
  agent::validate(service.agent());
  return service;
}

dds::ParticipantOptions ServiceConfig::participant_options(const std::string& own_role) const {
  dds::ParticipantOptions options = dds::participant_options(config_);
  options.domain_id = domain_id_;
  options.profiles_file = dds_profile_;
  options.security_role = dds::security_role(config_, own_role);
  return options;
}

agent::AgentConfig ServiceConfig::agent() const {
  const std::string preset = config_.preset().empty() ? kDefaultPreset : config_.preset();
  agent::AgentConfig agent = agent::preset(preset);
  for (const auto& [key, value] : config_.values()) {
    if (!key.starts_with(kAgentPrefix)) continue;
    const std::string agent_key = key.substr(std::string(kAgentPrefix).size());
    std::string text;
    if (const auto* number = std::get_if<double>(&value)) {
      text = number_text(*number);
    } else if (const auto* flag = std::get_if<bool>(&value)) {
      text = *flag ? "true" : "false";
    } else {
      text = std::get<std::string>(value);
    }
    agent::set_config_value(agent, agent_key, text);
  }
  agent.seed = static_cast<std::uint64_t>(config_.get<std::int64_t>("run.seed"));
  return agent;
}

agent::AgentConfig ServiceConfig::training_agent(const char* log_tag) const {
  agent::AgentConfig config = agent();
  if (const auto known = agent::run_precision(config, run_dir())) {
    config.precision = std::string(nn::to_string(known->precision));
    INDRIVE_LOG(kInfo, log_tag) << known->describe();
  }
  return config;
}

void ServiceConfig::note_agent_precision(const agent::Agent& agent, const char* log_tag) const {
  const agent::PrecisionChoice& choice = agent.precision_choice();
  if (choice.source.rfind("measured in", 0) != 0) return;  // training_agent logged it
  INDRIVE_LOG(kInfo, log_tag) << choice.describe();
  agent::record_run_precision(agent.config(), choice, run_dir());
}

std::map<std::string, std::string> ServiceConfig::agent_choices() const {
  std::map<std::string, std::string> choices;
  if (!config_.preset().empty()) choices["preset"] = config_.preset_origin();
  for (const auto& [key, value] : config_.values()) {
    if (!key.starts_with(kAgentPrefix)) continue;
    std::string origin = config_.origin(key);
    if (!origin.empty()) choices[key.substr(std::string(kAgentPrefix).size())] = std::move(origin);
  }
  return choices;
}

msg::Phase ServiceConfig::wire_phase() const { return to_wire(agent().phase); }

msg::Phase to_wire(agent::Phase phase) {
  switch (phase) {
    case agent::Phase::kPretrain:
      return msg::PHASE_PRETRAIN;
    case agent::Phase::kFinetune:
      return msg::PHASE_FINETUNE;
    case agent::Phase::kDreamer:
      return msg::PHASE_DREAMER;
  }
  return msg::PHASE_PRETRAIN;
}

std::string architecture_descriptor(const agent::AgentConfig& config) {
  const auto& wm = config.world_model;
  const bool task_actor = config.phase != agent::Phase::kPretrain;
  return "image=" + std::to_string(wm.image) + " channels=" + std::to_string(wm.channels) +
         " cnn_depth=" + std::to_string(wm.cnn_depth) + " deter=" + std::to_string(wm.deter) +
         " units=" + std::to_string(wm.units) + " stoch=" + std::to_string(wm.stoch) + "x" +
         std::to_string(wm.classes) + " head_layers=" + std::to_string(wm.head_layers) +
         " actor=" + (task_actor ? "task_actor:" : "expl_actor:") +
         std::to_string(config.behavior.units) + "x" + std::to_string(config.behavior.layers);
}

}  // namespace indrive::service
