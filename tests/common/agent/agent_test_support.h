// What the agent's tests share: a tiny fp32 configuration, replay filled from the dot
// environment, and parameter values read back by name.
#pragma once

#include <string>
#include <vector>

#include "dot_env.h"
#include "indrive/agent/agent.h"

namespace indrive::agent::test_support {

inline AgentConfig tiny_config(Phase phase = Phase::kPretrain, Method method = Method::kDisag) {
  AgentConfig c = preset("tiny");
  c.phase = phase;
  c.intrinsic.method = method;
  c.behavior.horizon = 5;  // short rollouts keep the unit tests fast
  c.seed = 17;
  // The tests compare agents bitwise (across thread counts, resumes, phases): "auto" could
  // measure bf16 faster for one of them and not for another.
  c.precision = "fp32";
  return c;
}

inline ReplayBuffer dot_replay(bool rewards, int steps = 200) {
  ReplayBuffer replay(
      {.capacity = 5000, .height = 32, .width = 32, .has_rewards = rewards, .seed = 4});
  synthetic::DotEnv env(32, 6);
  synthetic::collect_random(env, replay, steps, 8);
  return replay;
}

inline  // A random-action replay of the dot environment whose episodes end in a terminal event, as
    // the task's episodes do when they leave the route or reach the destination.
    ReplayBuffer
    dot_replay_with_terminals(int steps = 400) {
  ReplayBuffer replay(
      {.capacity = 5000, .height = 32, .width = 32, .has_rewards = true, .seed = 5});
  synthetic::DotEnv env(32, 6, /*episode_length=*/10);
  synthetic::collect_random(env, replay, steps, 9, /*terminal_ends=*/true);
  return replay;
}

inline std::vector<float> values_named(const nn::ParamGroup& group, bool cont_head) {
  std::vector<float> out;
  for (const auto& p : group.params()) {
    if (p->name().starts_with("cont.") != cont_head) continue;
    out.insert(out.end(), p->value().begin(), p->value().end());
  }
  return out;
}

}  // namespace indrive::agent::test_support
