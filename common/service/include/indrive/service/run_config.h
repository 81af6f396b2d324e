// The configuration of one run of the actor-learner service, shared by every program of a run
// (indrive-actor, indrive-learner, indrive-train-local): one schema (agent, environment, actor,
// learner, evaluation and DDS keys, with the presets tiny / cpu / small) and the architecture
// descriptor that snapshots carry. The typed views of a folder's own keys live in that folder
// (actor::env_config for env.*); this layer only knows them as keys.
//
//   ServiceOptions cli = ...;                       // --config, --run-dir, --domain, --set
//   ServiceConfig service = ServiceConfig::resolve(cli);
//   agent::AgentConfig agent = service.agent();      // sizes of the preset
//   std::string arch = architecture_descriptor(agent);
#pragma once

#include <cstdint>
#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include "indrive/agent/agent_config.h"
#include "indrive/basics/config.h"
#include "indrive/dds/participant.h"
#include "indrive/msg/trajectory.h"

namespace indrive::agent {
class Agent;
}  // namespace indrive::agent

namespace indrive::service {

// What both executables read from their command line (fixed by `indrive launch`).
struct ServiceOptions {
  std::filesystem::path config_file;   // --config; empty: schema defaults
  std::filesystem::path run_dir;       // --run-dir; its last component is the run id
  int domain_id = -1;                  // --domain; -1: the config's dds.domain_id
  std::string dds_profile;             // --dds-profile; empty: config, env var, then built-in
  std::string discovery_server;        // --discovery-server HOST:PORT; empty: config, env var
  std::string dds_security;            // --dds-security; empty: config's dds.security_dir
  std::vector<std::string> overrides;  // --set key=value, in order
  bool check_only = false;             // --check-config: resolve, summarise and exit
};

// Declares every key of a service run (agent.*, env.*, actor.*, learner.*, run.*, dds.*) and
// the presets tiny, cpu and small (which change only the agent's sizes).
void declare_service_schema(config::Schema& schema);

// The schema of a service run, built once.
const config::Schema& service_schema();

// A resolved run configuration with typed accessors for what the processes need.
class ServiceConfig {
 public:
  // Resolves defaults -> preset -> file -> --set, applies --domain, --dds-profile and
  // --dds-security, and checks that the agent part is usable. Throws config::ConfigError or
  // agent::AgentConfigError with what is wrong.
  static ServiceConfig resolve(const ServiceOptions& options);

  const config::Config& config() const { return config_; }
  // The run id: the last component of the run directory.
  const std::string& run_id() const { return run_id_; }
  const std::filesystem::path& run_dir() const { return run_dir_; }
  int domain_id() const { return domain_id_; }
  // The XML profiles file to load (never empty: falls back to the shipped single-host one).
  const std::string& dds_profile() const { return dds_profile_; }
  // What a participant of this run is made from: domain, profiles file and the dds.* keys
  // (discovery server, security folder); `own_role` is the security role when dds.security_role
  // is empty ("learner", "actor" or "evaluator").
  dds::ParticipantOptions participant_options(const std::string& own_role) const;

  // The agent's configuration (preset sizes plus every agent.* key).
  agent::AgentConfig agent() const;
  // agent() for the process that trains it: precision "auto" settled where it is known (this
  // run's <run>/precision.txt from a measurement on this CPU, or a measurement earlier in this
  // process; logged under `log_tag`), else left "auto" for the agent to measure itself.
  agent::AgentConfig training_agent(const char* log_tag) const;
  // Once the training agent is made: logs what its "auto" measured and keeps it in
  // <run>/precision.txt, so that a restarted learner trains on in the same precision.
  void note_agent_precision(const agent::Agent& agent, const char* log_tag) const;
  // The agent keys this configuration chose (a preset, a config file, --set), each with where
  // it was chosen: "preset" -> "--set preset=tiny", "world_model.deter" -> "preset 'tiny'" or
  // "--set agent.world_model.deter=64". Keys left at the defaults are not in it.
  std::map<std::string, std::string> agent_choices() const;
  // The wire phase of the agent's phase.
  msg::Phase wire_phase() const;

 private:
  explicit ServiceConfig(config::Config config) : config_(std::move(config)) {}
  config::Config config_;
  std::string run_id_;
  std::filesystem::path run_dir_;
  int domain_id_ = 0;
  std::string dds_profile_;
};

// The sizes that decide whether snapshot parameters fit a model, as one line such as
// "image=32 channels=3 cnn_depth=8 deter=128 units=128 stoch=16x16 head_layers=2
// actor=expl_actor:128x2". Actors compare it with a snapshot's `architecture` field.
std::string architecture_descriptor(const agent::AgentConfig& config);

// The wire phase of an agent phase.
msg::Phase to_wire(agent::Phase phase);

}  // namespace indrive::service
