// Acting: the actor processes' policy, built only from the parameters a snapshot carries
// (world model encoder/RSSM and the acting actor), and a random policy for prefill.
//
//   Policy policy(config);                       // sizes from the preset
//   policy.load_snapshot(snapshot_bytes);        // throws nn::SerializationError on mismatch
//   PolicyState state;
//   int action = policy.act(frame, /*is_first=*/true, state, /*sample=*/true);
#pragma once

#include <cstdint>
#include <memory>
#include <random>
#include <span>
#include <string>
#include <vector>

#include "indrive/agent/agent_config.h"
#include "indrive/agent/world_model.h"
#include "indrive/nn/nn.h"

namespace indrive::agent {

// Whether a policy snapshot (Agent::snapshot) carries a parameter: everything of the actor
// groups, and of the world model what acting runs, the encoder and the RSSM
// (WorldModel::acts_with). The decoder and the continuation head, 42% of a tiny world
// model's parameters, serve only training and stay out of snapshots.
bool snapshot_keeps(const std::string& group, const std::string& param);

// Recurrent state an actor carries between steps (plain vectors: no graph tensors survive).
struct PolicyState {
  std::vector<float> deter;  // (deter) h_t
  std::vector<float> stoch;  // (stoch * classes) s_t
  int action = 0;            // the previous action
};

// The acting policy: posterior step on the new frame, then the actor.
class Policy {
 public:
  // Builds the networks with the config's sizes; the acting actor is the exploration actor in
  // pretrain and the task actor otherwise. Parameters stay random until load_snapshot.
  explicit Policy(const AgentConfig& config);
  // Loads parameters from Agent::snapshot() bytes; throws nn::SerializationError when the
  // snapshot holds other groups or sizes, leaving the policy unchanged. A snapshot written
  // before snapshots left out what acting does not run (the whole world model) loads too.
  void load_snapshot(std::span<const std::uint8_t> snapshot);
  // Returns the action for `frame` ((H, W) class ids) and updates `state`. is_first starts an
  // episode (state and previous action are reset). With sample false the most likely action
  // is taken. Resets the calling thread's graph: call it between training steps, not inside.
  int act(std::span<const std::uint8_t> frame, bool is_first, PolicyState& state, bool sample);
  // Evaluation acting: a sample (config.eval_sample, the default) or the most likely action.
  int act_eval(std::span<const std::uint8_t> frame, bool is_first, PolicyState& state) {
    return act(frame, is_first, state, config_.eval_sample);
  }
  // Restarts the generator behind sampled latents and actions: an evaluation episode seeded
  // by its spec acts the same whatever ran before it (or on which evaluator).
  void reseed(std::uint64_t seed) { rng_ = nn::Rng(seed ^ 0x9e3779b97f4a7c15ull); }
  // Action probabilities of the last act() call (9 values).
  const std::vector<float>& last_probs() const { return last_probs_; }
  // With `keep` set, act() also keeps the encoder's embedding of its frame (embed_dim values),
  // what the frame alone tells the policy; the route probe (tools/route_probe/) reads it.
  void keep_embedding(bool keep) { keep_embedding_ = keep; }
  const std::vector<float>& last_embedding() const { return last_embedding_; }
  std::uint64_t loaded_snapshots() const { return loaded_; }

 private:
  AgentConfig config_;
  nn::Rng rng_;
  std::unique_ptr<WorldModel> wm_;
  nn::ParamGroup actor_params_;
  nn::Mlp actor_;
  std::vector<float> last_probs_;
  bool keep_embedding_ = false;
  std::vector<float> last_embedding_;
  std::uint64_t loaded_ = 0;
};

// Uniformly random actions for prefill, seeded.
class RandomPolicy {
 public:
  explicit RandomPolicy(std::uint64_t seed) : rng_(seed) {}
  // A uniform action in [0, 9).
  int act() { return static_cast<int>(pick_(rng_)); }

 private:
  std::mt19937_64 rng_;
  std::uniform_int_distribution<int> pick_{0, kNumActions - 1};
};

}  // namespace indrive::agent
