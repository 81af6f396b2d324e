#include "indrive/agent/policy.h"

#include "indrive/agent/observation.h"
#include "indrive/basics/check.h"

namespace indrive::agent {

using nn::Shape;
using nn::Tensor;

namespace {
std::string actor_group_name(Phase phase) {
  return phase == Phase::kPretrain ? "expl_actor" : "task_actor";
}
}  // namespace

bool snapshot_keeps(const std::string& group, const std::string& param) {
  return group != "world_model" || WorldModel::acts_with(param);
}

Policy::Policy(const AgentConfig& config)
    : config_(config),
      rng_(config.seed ^ 0x9e3779b97f4a7c15ull),
      actor_params_(actor_group_name(config.phase)) {
  validate(config_);
  nn::flush_denormals();
  nn::Rng init(config.seed);
  wm_ = std::make_unique<WorldModel>(config_.world_model, init);
  // Same layer names and options as ActorCritic's actor, so snapshot groups load one to one.
  actor_ = nn::Mlp(actor_params_, "actor", config_.world_model.feat_dim(),
                   {.units = config_.behavior.units,
                    .layers = config_.behavior.layers,
                    .out = kNumActions,
                    .one_hot_from = config_.world_model.deter},
                   init);
}

void Policy::load_snapshot(std::span<const std::uint8_t> snapshot) {
  nn::ParamGroup* groups[2] = {&wm_->params(), &actor_params_};
  const std::span<nn::ParamGroup* const> parts(groups, 2);
  try {
    nn::load_params(snapshot, parts, snapshot_keeps);
  } catch (const nn::SerializationError& error) {
    // A snapshot of the whole world model (written before snapshots left the decoder out)?
    // Otherwise the error of the current form is the one that says what is wrong.
    try {
      nn::load_params(snapshot, parts);
    } catch (const nn::SerializationError&) {
      throw error;
    }
  }
  ++loaded_;
}

int Policy::act(std::span<const std::uint8_t> frame, bool is_first, PolicyState& state,
                bool sample) {
  const WorldModelConfig& w = config_.world_model;
  INDRIVE_CHECK_EQ(frame.size(), static_cast<std::size_t>(w.image) * w.image);
  nn::Graph& graph = nn::current_graph();
  graph.reset();
  nn::NoGradGuard no_grad;
  const bool fresh = is_first || state.deter.empty();
  RssmState prev;
  if (fresh) {
    prev = wm_->initial(1);
  } else {
    prev.deter = nn::constant(Shape{1, w.deter}, state.deter);
    prev.stoch = nn::constant(Shape{1, w.stoch_dim()}, state.stoch);
  }
  Tensor image = nn::empty(Shape{1, w.image, w.image, 3});
  class_ids_to_rgb(frame, image.values());
  Tensor action = WorldModel::one_hot({fresh ? 0 : state.action});
  if (fresh) action = nn::zeros(Shape{1, kNumActions});
  const float first[1] = {fresh ? 1.0f : 0.0f};
  Tensor embed = wm_->encode(image);
  if (keep_embedding_) last_embedding_.assign(embed.values().begin(), embed.values().end());
  RssmState next = wm_->obs_step(prev, action, embed, nn::constant(Shape{1, 1}, first), rng_);
  Tensor probs = nn::unimix_probs(actor_(WorldModel::features(next)), kNumActions,
                                  config_.behavior.actor_unimix);
  last_probs_.assign(probs.values().begin(), probs.values().end());
  int chosen = 0;
  if (sample) {
    const float u = rng_.uniform();
    float acc = 0.0f;
    chosen = kNumActions - 1;
    for (int a = 0; a < kNumActions; ++a) {
      acc += last_probs_[a];
      if (u < acc) {
        chosen = a;
        break;
      }
    }
  } else {
    for (int a = 1; a < kNumActions; ++a)
      if (last_probs_[a] > last_probs_[chosen]) chosen = a;
  }
  state.deter.assign(next.deter.values().begin(), next.deter.values().end());
  state.stoch.assign(next.stoch.values().begin(), next.stoch.values().end());
  state.action = chosen;
  return chosen;
}

}  // namespace indrive::agent
