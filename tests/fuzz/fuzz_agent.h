// The agent the fuzz targets of agent formats load into (snapshots, checkpoints, replay files).
// Separate from fuzz_support.h so that the targets of other modules link no agent.
#pragma once

#include <string>
#include <utility>
#include <vector>

#include "indrive/agent/agent_config.h"

namespace indrive::fuzz {

// An agent small enough that its snapshots and checkpoints are a few hundred KB, so a target
// runs many inputs a second; the format and the loaders are the ones of every preset.
inline agent::AgentConfig micro_agent(agent::Phase phase = agent::Phase::kPretrain) {
  agent::AgentConfig config = agent::preset("tiny");
  config.phase = phase;
  for (const auto& [key, value] :
       std::vector<std::pair<std::string, std::string>>{{"world_model.image", "16"},
                                                        {"world_model.cnn_depth", "4"},
                                                        {"world_model.deter", "16"},
                                                        {"world_model.units", "16"},
                                                        {"world_model.stoch", "4"},
                                                        {"world_model.classes", "4"},
                                                        {"intrinsic.ensemble", "2"},
                                                        {"intrinsic.units", "16"},
                                                        {"behavior.units", "16"},
                                                        {"behavior.horizon", "3"}}) {
    agent::set_config_value(config, key, value);
  }
  config.replay.capacity = 256;
  config.replay.batch = 2;
  config.replay.length = 4;
  agent::validate(config);
  return config;
}

}  // namespace indrive::fuzz
