#include "indrive/agent/behavior.h"

#include <algorithm>
#include <cmath>
#include <functional>
#include <vector>

#include "indrive/basics/check.h"

namespace indrive::agent {

using nn::Shape;
using nn::Tensor;

namespace {

Tensor column(Tensor x) { return nn::reshape(x, Shape{x.numel(), 1}); }

// Rows per task of row_values().
constexpr std::int64_t kValueChunkRows = 512;

}  // namespace

std::vector<float> row_values(Tensor x, const std::function<Tensor(Tensor)>& fn) {
  const std::int64_t rows = x.dim(0);
  std::vector<float> out(static_cast<std::size_t>(rows));
  const std::int64_t chunks = (rows + kValueChunkRows - 1) / kValueChunkRows;
  nn::parallel_tasks(chunks, [&](std::int64_t c) {
    const std::int64_t r0 = c * kValueChunkRows, r1 = std::min(rows, r0 + kValueChunkRows);
    const Tensor v = fn(nn::slice(x, r0, r1, 0));
    INDRIVE_CHECK_EQ(v.numel(), r1 - r0) << "row_values: one value per row";
    std::copy_n(v.data(), r1 - r0, out.data() + r0);
  });
  return out;
}

Tensor ImaginedTrajectory::state_features() const {
  return nn::slice(features, 0, static_cast<std::int64_t>(horizon) * n, 0);
}

Tensor ImaginedTrajectory::next_features() const {
  return nn::slice(features, n, static_cast<std::int64_t>(horizon + 1) * n, 0);
}

ActorCritic::ActorCritic(const std::string& prefix, const BehaviorConfig& config, int feat_dim,
                         nn::Rng& rng, int one_hot_from)
    : config_(config),
      actor_params_(prefix + "_actor"),
      critic_params_(prefix + "_critic"),
      slow_params_(prefix + "_slow_critic"),
      actor_(actor_params_, "actor", feat_dim,
             {.units = config.units,
              .layers = config.layers,
              .out = kNumActions,
              .one_hot_from = one_hot_from},
             rng),
      critic_(critic_params_, "critic", feat_dim,
              {.units = config.units,
               .layers = config.layers,
               .out = nn::kTwoHotBins,
               .out_init = nn::Init::kZeros,
               .one_hot_from = one_hot_from},
              rng),
      slow_critic_(slow_params_, "critic", feat_dim,
                   {.units = config.units,
                    .layers = config.layers,
                    .out = nn::kTwoHotBins,
                    .out_init = nn::Init::kZeros,
                    .one_hot_from = one_hot_from},
                   rng),
      return_norm_(config.return_low, config.return_high, config.return_decay,
                   config.return_floor) {
  actor_opt_ = std::make_unique<nn::Adam>(
      actor_params_, nn::AdamConfig{.lr = config.actor_lr, .eps = config.eps, .clip = config.clip});
  critic_opt_ = std::make_unique<nn::Adam>(
      critic_params_,
      nn::AdamConfig{.lr = config.critic_lr, .eps = config.eps, .clip = config.clip});
  slow_update_ = std::make_unique<nn::Ema>(critic_params_, slow_params_, config.slow_critic_rate);
  slow_update_->copy();
}

Tensor ActorCritic::action_probs(Tensor features) {
  return nn::unimix_probs(actor_(features), kNumActions, config_.actor_unimix);
}

ImaginedTrajectory ActorCritic::imagine(WorldModel& wm, const RssmState& start, nn::Rng& rng,
                                        std::vector<float> start_cont) {
  nn::NoGradGuard no_grad;
  ImaginedTrajectory traj;
  traj.horizon = config_.horizon;
  traj.n = static_cast<int>(start.deter.dim(0));
  INDRIVE_CHECK(start_cont.empty() || static_cast<int>(start_cont.size()) == traj.n)
      << "start_cont has " << start_cont.size() << " entries for " << traj.n << " start states";
  traj.start_cont = std::move(start_cont);
  const std::int64_t n = traj.n, h = traj.horizon;
  const std::int64_t deter = start.deter.dim(1), feat = deter + start.stoch.dim(1);
  traj.features = nn::empty(Shape{(h + 1) * n, feat});
  traj.actions = nn::empty(Shape{h * n, kNumActions});
  traj.cont.resize(static_cast<std::size_t>(h * n));
  const Tensor start_deter = nn::stop_gradient(start.deter);
  const Tensor start_stoch = nn::stop_gradient(start.stoch);
  // Rows of a step of one chunk into the trajectory's time-major tables (row t * N + i).
  auto put = [](Tensor from, Tensor to, std::int64_t row, std::int64_t col) {
    const std::int64_t width = from.dim(1), stride = to.dim(1);
    for (std::int64_t r = 0; r < from.dim(0); ++r)
      std::copy_n(from.data() + r * width, width, to.data() + (row + r) * stride + col);
  };
  // The start states are rolled out in chunks of a fixed size, each on one thread and its own
  // graph, with its own random stream drawn from `rng`: the rollout is H steps of ops on N rows,
  // too small to split op by op (on the tiny preset it ran on one of two threads), while the
  // chunks are independent. Fixed chunks and streams keep the trajectory the same for any
  // thread count.
  const std::uint64_t seed = rng.next_u64();
  const std::int64_t chunks = (n + kImagineChunkRows - 1) / kImagineChunkRows;
  nn::parallel_tasks(chunks, [&](std::int64_t c) {
    const std::int64_t r0 = c * kImagineChunkRows, r1 = std::min(n, r0 + kImagineChunkRows);
    nn::Rng chunk_rng(seed + static_cast<std::uint64_t>(c) * 0x9E3779B97F4A7C15ull);
    RssmState state{nn::slice(start_deter, r0, r1, 0), nn::slice(start_stoch, r0, r1, 0)};
    put(state.deter, traj.features, r0, 0);
    put(state.stoch, traj.features, r0, deter);
    std::vector<Tensor> next(h);
    for (std::int64_t t = 0; t < h; ++t) {
      const Tensor action = nn::sample_straight_through(action_probs(WorldModel::features(state)),
                                                        kNumActions, chunk_rng);
      state = wm.img_step(state, action, chunk_rng);
      next[t] = WorldModel::features(state);
      put(action, traj.actions, t * n + r0, 0);
      put(state.deter, traj.features, (t + 1) * n + r0, 0);
      put(state.stoch, traj.features, (t + 1) * n + r0, deter);
    }
    // The continuation of the chunk's imagined states, in one pass over its H steps rather
    // than one per step: the head reads nothing but the state, so the loop does not need it.
    const Tensor cont = nn::sigmoid(wm.cont_logits(nn::concat(next, 0)));
    const std::int64_t rows = r1 - r0;
    for (std::int64_t t = 0; t < h; ++t)
      std::copy_n(cont.data() + t * rows, rows, traj.cont.data() + t * n + r0);
  });
  return traj;
}

Tensor ActorCritic::loss(const ImaginedTrajectory& traj, const std::vector<float>& rewards,
                         BehaviorMetrics* metrics) {
  const int h = traj.horizon, n = traj.n;
  const std::int64_t rows = static_cast<std::int64_t>(h) * n;
  INDRIVE_CHECK_EQ(static_cast<std::int64_t>(rewards.size()), rows);
  Tensor states = nn::stop_gradient(traj.state_features());  // (H * N, feat)

  // The critic's logits of the H * N start states, recorded for the critic loss below; their
  // values also serve the returns, so the critic runs once more only on the N last states.
  Tensor logits = critic_(states);
  // Values of all H + 1 states, lambda-returns, cumulative-discount weights (no tape).
  std::vector<float> values =
      row_values(nn::stop_gradient(logits), [](Tensor l) { return nn::twohot_mean(l); });
  const std::vector<float> last = row_values(nn::slice(traj.features, rows, rows + n, 0),
                                             [&](Tensor u) { return nn::twohot_mean(critic_(u)); });
  values.insert(values.end(), last.begin(), last.end());
  const std::vector<float> slow_values =
      row_values(states, [&](Tensor u) { return nn::twohot_mean(slow_critic_(u)); });
  const std::vector<float> returns =
      lambda_returns(rewards, traj.cont, values, h, n, config_.gamma, config_.lambda);
  std::vector<float> weights(rows);
  for (int i = 0; i < n; ++i) weights[i] = traj.start_cont.empty() ? 1.0f : traj.start_cont[i];
  for (int t = 1; t < h; ++t) {
    for (int i = 0; i < n; ++i) {
      weights[t * n + i] = weights[(t - 1) * n + i] * config_.gamma * traj.cont[(t - 1) * n + i];
    }
  }
  return_norm_.update(returns);
  const float scale = return_norm_.scale();
  std::vector<float> advantage(rows);
  for (std::int64_t k = 0; k < rows; ++k) advantage[k] = (returns[k] - values[k]) / scale;

  Tensor weight = nn::constant(Shape{rows, 1}, weights);
  const float inv_rows = 1.0f / static_cast<float>(rows);
  // REINFORCE with the entropy bonus: -w * (log pi(a_t | u_t) * adv_t + eta * H[pi(. | u_t)]).
  Tensor probs = action_probs(states);
  Tensor logp = column(nn::sum(nn::mul(traj.actions, nn::log(probs)), -1));
  Tensor entropy = column(nn::entropy(probs));
  Tensor objective = nn::add(nn::mul(logp, nn::constant(Shape{rows, 1}, advantage)),
                             nn::scale(entropy, config_.entropy));
  Tensor actor_loss = nn::scale(nn::sum(nn::mul(objective, weight)), -inv_rows);
  // Two-hot critic towards the returns, regularised towards the slow critic's values.
  Tensor ce = column(nn::twohot_cross_entropy(logits, nn::constant(Shape{rows}, returns)));
  Tensor reg = column(nn::twohot_cross_entropy(logits, nn::constant(Shape{rows}, slow_values)));
  Tensor critic_loss = nn::scale(
      nn::sum(nn::mul(nn::add(ce, nn::scale(reg, config_.slow_critic_reg)), weight)), inv_rows);
  if (metrics != nullptr) {
    metrics->actor_loss = actor_loss.item();
    metrics->critic_loss = critic_loss.item();
    float ent = 0, ret = 0, rew = 0, val = 0;
    for (float e : entropy.values()) ent += e;
    for (float r : returns) ret += r;
    for (float r : rewards) rew += r;
    for (std::int64_t k = 0; k < rows; ++k) val += values[k];
    metrics->value_mean = val * inv_rows;
    metrics->entropy = ent * inv_rows;
    metrics->return_mean = ret * inv_rows;
    metrics->reward_mean = rew * inv_rows;
    metrics->return_scale = scale;
  }
  return nn::add(actor_loss, critic_loss);
}

void ActorCritic::step() {
  actor_opt_->step();
  critic_opt_->step();
  slow_update_->update();
}

void ActorCritic::copy_actor_from(const ActorCritic& other) {
  const auto& src = other.actor_params_.params();
  const auto& dst = actor_params_.params();
  INDRIVE_CHECK_EQ(src.size(), dst.size()) << "actors of different sizes";
  for (std::size_t i = 0; i < src.size(); ++i) {
    INDRIVE_CHECK(src[i]->shape() == dst[i]->shape()) << src[i]->name();
    std::copy(src[i]->value().begin(), src[i]->value().end(), dst[i]->value().begin());
  }
}

}  // namespace indrive::agent
