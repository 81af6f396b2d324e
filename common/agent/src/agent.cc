#include "indrive/agent/agent.h"

#include <chrono>
#include <cmath>

#include "indrive/agent/policy.h"
#include "indrive/basics/check.h"
#include "indrive/nn/kernels.h"

namespace indrive::agent {

using nn::Shape;
using nn::Tensor;

// Seconds since the last call (or construction), and the product FLOPs in that time
// (nn::gemm_flops, into *flops): one stage of an update at a time.
class Agent::StageClock {
 public:
  double lap(double* flops) {
    const auto now = std::chrono::steady_clock::now();
    const double s = std::chrono::duration<double>(now - last_).count();
    const std::uint64_t f = nn::gemm_flops();
    *flops = static_cast<double>(f - flops_);
    last_ = now, flops_ = f;
    return s;
  }

 private:
  std::chrono::steady_clock::time_point last_ = std::chrono::steady_clock::now();
  std::uint64_t flops_ = nn::gemm_flops();
};

TrainMetrics StepTiming::as_metrics() const {
  auto f = [](double s) { return static_cast<float>(s); };
  return {{"time/world_model_s", f(world_model)}, {"time/intrinsic_s", f(intrinsic)},
          {"time/imagine_s", f(imagine)},         {"time/reward_s", f(reward)},
          {"time/behavior_s", f(behavior)},       {"time/backward_s", f(backward)},
          {"time/optimizers_s", f(optimizers)},   {"time/update_s", f(total())}};
}

Agent::Agent(const AgentConfig& config) : config_(config), rng_(config.seed) {
  validate(config_);
  const std::optional<PrecisionChoice> known = known_precision(config_);
  // Until it is measured (below), an "auto" agent is built in fp32 (building runs no product).
  nn::set_precision(known ? known->precision : nn::Precision::kFp32);
  nn::flush_denormals();
  wm_ = std::make_unique<WorldModel>(config_.world_model, rng_);
  intrinsic_ = make_intrinsic(config_.intrinsic, config_.world_model, rng_);
  expl_ = std::make_unique<ActorCritic>("expl", config_.behavior, config_.world_model.feat_dim(),
                                        rng_, config_.world_model.deter);
  task_ = std::make_unique<ActorCritic>("task", config_.behavior, config_.world_model.feat_dim(),
                                        rng_, config_.world_model.deter);
  const WorldModelConfig& w = config_.world_model;
  wm_opt_ = std::make_unique<nn::Adam>(wm_->params(),
                                       nn::AdamConfig{.lr = w.lr, .eps = w.eps, .clip = w.clip});
  reward_opt_ = std::make_unique<nn::Adam>(
      wm_->reward_params(), nn::AdamConfig{.lr = w.lr, .eps = w.eps, .clip = w.clip});
  cont_opt_ = std::make_unique<nn::Adam>(
      wm_->params(), nn::AdamConfig{.lr = w.lr, .eps = w.eps, .clip = w.clip}, "cont.");
  if (config_.phase == Phase::kFinetune) set_phase(Phase::kFinetune);
  precision_ = known ? *known : measure_precision(*this);
  nn::set_precision(precision_.precision);
  timing_ = {}, flops_ = {};  // the measurement's updates are no update of this agent
}

void Agent::set_phase(Phase phase) {
  config_.phase = phase;
  // The task actor starts from the exploration actor once; its critic stays fresh.
  if (phase == Phase::kFinetune && !task_actor_initialised_) {
    task_->copy_actor_from(*expl_);
    task_actor_initialised_ = true;
  }
}

std::string Agent::acting_actor_group() const {
  return config_.phase == Phase::kPretrain ? expl_->actor_params().name()
                                           : task_->actor_params().name();
}

void Agent::check_batch(const SequenceBatch& batch) const {
  const Phase phase = config_.phase;
  if (phase == Phase::kPretrain && !batch.rewards.empty()) {
    throw AgentError(
        "a pretraining batch carries rewards; pretraining must be reward-free "
        "(make the replay buffer with has_rewards = false)");
  }
  if (phase != Phase::kPretrain && batch.rewards.empty()) {
    throw AgentError(std::string("a ") + std::string(to_string(phase)) +
                     " batch has no rewards; task phases need a replay buffer with rewards");
  }
}

bool Agent::trains_world_model() const {
  // Trained in pretrain and dreamer, a frozen feature extractor in finetune (unless
  // agent.finetune_world_model trains it there too).
  return config_.phase != Phase::kFinetune || config_.finetune_world_model;
}

WorldModelOutput Agent::world_model_loss(const SequenceBatch& batch, std::vector<Tensor>& losses,
                                         TrainMetrics& metrics) {
  const Phase phase = config_.phase;
  const bool task_phase = phase != Phase::kPretrain;
  const int b = batch.batch, t = batch.length;
  WorldModelOutput out;
  if (!trains_world_model()) {
    {
      nn::NoGradGuard frozen;
      out = wm_->observe(batch, false, rng_);
    }
    Tensor target = WorldModel::time_major_column(batch.rewards, b, t);
    const Tensor features = nn::stop_gradient(out.features);
    Tensor loss = nn::mean(nn::twohot_cross_entropy(wm_->reward_logits(features), target));
    out.reward = loss.item();
    // The continuation head: trained with agent.finetune_cont (on stop-gradient features, like
    // the reward head), else frozen as observe() ran it.
    if (config_.finetune_cont) {
      out.cont_logits = wm_->cont_logits(features);
      const Tensor is_terminal = WorldModel::time_major_column(batch.is_terminal, b, t);
      const Tensor cont =
          nn::mean(nn::bce_with_logits(out.cont_logits, nn::rsub_scalar(1.0f, is_terminal)));
      out.cont = cont.item();
      loss = nn::add(loss, nn::scale(cont, config_.world_model.cont_scale));
    }
    losses.push_back(loss);
  } else {
    out = wm_->observe(batch, task_phase, rng_);
    losses.push_back(out.loss);
  }
  // Few-shot logs the continuation head's mean prediction at the batch's terminal steps
  // (pretraining never showed it the task's terminal events).
  if (phase == Phase::kFinetune) {
    double at_terminal = 0.0;
    int terminals = 0;
    for (std::size_t i = 0; i < batch.is_terminal.size(); ++i) {
      // is_terminal is batch-major, the logits time-major.
      if (batch.is_terminal[i] == 0.0f) continue;
      const std::size_t row = WorldModel::time_major_row(i, b, t);
      at_terminal += 1.0 / (1.0 + std::exp(-static_cast<double>(out.cont_logits.data()[row])));
      ++terminals;
    }
    if (terminals > 0) metrics.emplace_back("wm/cont_at_terminal", at_terminal / terminals);
  }
  metrics.insert(metrics.end(), {{"wm/recon", out.recon},
                                 {"wm/kl", out.kl},
                                 {"wm/dyn", out.dyn},
                                 {"wm/rep", out.rep},
                                 {"wm/cont", out.cont}});
  if (task_phase) metrics.emplace_back("wm/reward", out.reward);
  return out;
}

Tensor Agent::intrinsic_loss(const SequenceBatch& batch, const WorldModelOutput& out,
                             TrainMetrics& metrics) {
  const int b = batch.batch, t = batch.length;
  Transitions tr = make_transitions(out.features, out.post_probs,
                                    WorldModel::action_one_hot(batch.actions, b, t),
                                    WorldModel::time_major_column(batch.is_first, b, t), b);
  Tensor loss = intrinsic_->loss(tr);
  metrics.emplace_back("intrinsic/loss", intrinsic_->last_loss());
  return loss;
}

ImaginedTrajectory Agent::imagine_from(const SequenceBatch& batch, const WorldModelOutput& out,
                                       ActorCritic& behavior) {
  const RssmState start{nn::stop_gradient(out.deter), nn::stop_gradient(out.stoch)};
  std::vector<float> start_cont;
  // Time-major like the posterior states: row t * B + i is step t of sequence i.
  Tensor terminal = WorldModel::time_major_column(batch.is_terminal, batch.batch, batch.length);
  start_cont.reserve(terminal.numel());
  for (float x : terminal.values()) start_cont.push_back(1.0f - x);
  return behavior.imagine(*wm_, start, rng_, std::move(start_cont));
}

std::vector<float> Agent::imagined_rewards(const ImaginedTrajectory& traj, TrainMetrics& metrics) {
  nn::NoGradGuard no_grad;
  if (config_.phase != Phase::kPretrain) {
    return row_values(traj.next_features(),
                      [&](Tensor u) { return nn::twohot_mean(wm_->reward_logits(u)); });
  }
  std::vector<float> rewards =
      intrinsic_->reward(traj.state_features(), traj.actions, traj.next_features());
  metrics.emplace_back("intrinsic/raw_reward", intrinsic_->last_raw_reward());
  metrics.emplace_back("intrinsic/raw_std", intrinsic_->last_raw_std());
  return rewards;
}

void Agent::backward_and_step(const std::vector<Tensor>& losses, ActorCritic& behavior,
                              TrainMetrics& metrics, StageClock& clock) {
  const Phase phase = config_.phase;
  // One backward for all losses: its independent parts side by side on the engine's threads,
  // or their sum with each op split over the threads. Only the optimisers of the parts that
  // train in this phase are stepped. With parts, the intrinsic module's and the actor-critic's
  // optimisers step inside their parts, on the thread that ran the part, while the world
  // model's part may still run (their time counts as backward); the first loss's optimisers
  // (world model, reward head) step afterwards over every thread.
  const int intrinsic_part = phase == Phase::kPretrain ? 1 : -1;
  const int behavior_part = static_cast<int>(losses.size()) - 1;
  auto step_part = [&](int i) {
    if (i == intrinsic_part) intrinsic_->step();
    if (i == behavior_part) behavior.step();
  };
  nn::Graph& graph = nn::current_graph();
  if (config_.backward_parts) {
    graph.backward(losses, step_part);
  } else {
    Tensor total = losses.front();
    for (std::size_t i = 1; i < losses.size(); ++i) total = nn::add(total, losses[i]);
    graph.backward(total);
  }
  timing_.backward = clock.lap(&flops_.backward);
  const bool train_wm = trains_world_model();
  if (train_wm) {
    const nn::StepStats s = wm_opt_->step();
    metrics.emplace_back("wm/grad_norm", s.grad_norm);
  }
  if (phase != Phase::kPretrain) reward_opt_->step();
  if (phase == Phase::kFinetune && config_.finetune_cont) cont_opt_->step();
  if (!config_.backward_parts)
    for (int i = 1; i < static_cast<int>(losses.size()); ++i) step_part(i);
  // Gradients that reached frozen parts (none should) are dropped, never applied later (the
  // optimisers that stepped have zeroed their own).
  if (!train_wm) wm_->params().zero_grad();
  if (phase != Phase::kPretrain) intrinsic_->params().zero_grad();
  timing_.optimizers = clock.lap(&flops_.optimizers);
}

TrainMetrics Agent::train_step(const SequenceBatch& batch) {
  check_batch(batch);
  const bool task_phase = config_.phase != Phase::kPretrain;
  StageClock clock;
  timing_ = {};
  flops_ = {};
  nn::current_graph().reset();
  TrainMetrics metrics;
  // The update's losses; stop-gradients keep each inside its own part of the model.
  std::vector<Tensor> losses;

  const WorldModelOutput out = world_model_loss(batch, losses, metrics);
  timing_.world_model = clock.lap(&flops_.world_model);
  // Intrinsic module: trained on replay transitions in pretraining only.
  if (!task_phase) {
    losses.push_back(intrinsic_loss(batch, out, metrics));
    timing_.intrinsic = clock.lap(&flops_.intrinsic);
  }
  // Behaviour in imagination from every posterior state.
  ActorCritic& behavior = task_phase ? *task_ : *expl_;
  const ImaginedTrajectory traj = imagine_from(batch, out, behavior);
  timing_.imagine = clock.lap(&flops_.imagine);
  const std::vector<float> rewards = imagined_rewards(traj, metrics);
  timing_.reward = clock.lap(&flops_.reward);
  BehaviorMetrics bm;
  losses.push_back(behavior.loss(traj, rewards, &bm));
  const std::string prefix = task_phase ? "task/" : "expl/";
  metrics.insert(metrics.end(), {{prefix + "reward", bm.reward_mean},
                                 {prefix + "return", bm.return_mean},
                                 {prefix + "return_scale", bm.return_scale},
                                 {prefix + "value", bm.value_mean},
                                 {prefix + "actor_loss", bm.actor_loss},
                                 {prefix + "critic_loss", bm.critic_loss},
                                 {prefix + "entropy", bm.entropy}});
  timing_.behavior = clock.lap(&flops_.behavior);

  backward_and_step(losses, behavior, metrics, clock);
  ++train_steps_;
  return metrics;
}

std::vector<std::uint8_t> Agent::snapshot() const {
  const nn::ParamGroup* actor =
      config_.phase == Phase::kPretrain ? &expl_->actor_params() : &task_->actor_params();
  const nn::ParamGroup* parts[2] = {&wm_->params(), actor};
  return nn::save_params(std::span<const nn::ParamGroup* const>(parts, 2), snapshot_keeps);
}

std::vector<nn::ParamGroup*> Agent::groups() {
  std::vector<nn::ParamGroup*> out = {&wm_->params(), &wm_->reward_params()};
  for (nn::ParamGroup* g : intrinsic_->groups()) out.push_back(g);
  for (ActorCritic* ac : {expl_.get(), task_.get()}) {
    out.push_back(&ac->actor_params());
    out.push_back(&ac->critic_params());
    out.push_back(&ac->slow_critic_params());
  }
  return out;
}

std::vector<const nn::ParamGroup*> Agent::groups() const {
  std::vector<nn::ParamGroup*> g = const_cast<Agent*>(this)->groups();
  return {g.begin(), g.end()};
}

std::vector<nn::Adam*> Agent::optimizers() const {
  return {wm_opt_.get(),
          reward_opt_.get(),
          &intrinsic_->optimizer(),
          &expl_->actor_optimizer(),
          &expl_->critic_optimizer(),
          &task_->actor_optimizer(),
          &task_->critic_optimizer()};
}

}  // namespace indrive::agent
