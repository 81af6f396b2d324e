#include "indrive/agent/world_model.h"

#include "indrive/agent/observation.h"
#include "indrive/basics/check.h"

namespace indrive::agent {

using nn::Shape;
using nn::Tensor;

WorldModel::WorldModel(const WorldModelConfig& config, nn::Rng& rng) : config_(config) {
  const int stoch_dim = config.stoch_dim();
  const nn::ConvStackOptions conv{
      .image = config.image, .channels = config.channels, .depth = config.cnn_depth, .min_res = 4};
  encoder_ = nn::ConvEncoder(params_, "enc", conv, rng);
  img_in_ = nn::Linear(params_, "rssm.img_in", stoch_dim + kNumActions, config.units,
                       nn::LinearOptions{.bias = false, .one_hot_from = 0}, rng);
  img_in_norm_ = nn::LayerNorm(params_, "rssm.img_in.norm", config.units);
  gru_ = nn::GruCell(params_, "rssm.gru", config.units, config.deter, rng);
  prior_head_ = nn::Mlp(params_, "rssm.prior", config.deter,
                        {.units = config.units, .layers = 1, .out = stoch_dim}, rng);
  post_head_ = nn::Mlp(params_, "rssm.post", config.deter + encoder_.embed_dim(),
                       {.units = config.units, .layers = 1, .out = stoch_dim}, rng);
  initial_ = &params_.add("rssm.initial", Shape{1, config.deter});
  // Features are [deter, stoch] and stoch is one-hot (a sample or a mode): the layers reading
  // features gather their stoch rows (linear_one_hot_tail), as img_in does for [stoch, action].
  nn::ConvStackOptions dec = conv;
  dec.one_hot_from = config.deter;
  decoder_ = nn::ConvDecoder(params_, "dec", config.feat_dim(), dec, rng);
  cont_head_ = nn::Mlp(
      params_, "cont", config.feat_dim(),
      {.units = config.units, .layers = config.head_layers, .out = 1, .one_hot_from = config.deter},
      rng);
  // Zero output weights make the first reward predictions exactly 0 (DreamerV3).
  reward_head_ = nn::Mlp(reward_params_, "reward", config.feat_dim(),
                         {.units = config.units,
                          .layers = config.head_layers,
                          .out = nn::kTwoHotBins,
                          .out_init = nn::Init::kZeros,
                          .one_hot_from = config.deter},
                         rng);
}

RssmState WorldModel::initial(int n) {
  Tensor h0 = nn::tanh(initial_->tensor());                        // (1, deter)
  Tensor deter = nn::add(nn::zeros(Shape{n, config_.deter}), h0);  // broadcast to (n, deter)
  Tensor probs = nn::unimix_probs(prior_head_(deter), config_.classes, config_.unimix);
  return {deter, nn::mode_one_hot(probs, config_.classes)};
}

Tensor WorldModel::next_deter(const RssmState& prev, Tensor action) {
  Tensor x = nn::silu(img_in_norm_(img_in_(nn::concat({prev.stoch, action}, -1))));
  return gru_(x, prev.deter);
}

Tensor WorldModel::prior_probs(Tensor deter) {
  return nn::unimix_probs(prior_head_(deter), config_.classes, config_.unimix);
}

RssmState WorldModel::img_step(const RssmState& prev, Tensor action, nn::Rng& rng,
                               Tensor* prior_probs_out) {
  Tensor deter = next_deter(prev, action);
  Tensor probs = prior_probs(deter);
  if (prior_probs_out != nullptr) *prior_probs_out = probs;
  return {deter, nn::sample_straight_through(probs, config_.classes, rng)};
}

RssmState WorldModel::obs_step(const RssmState& prev, Tensor action, Tensor embed, Tensor is_first,
                               nn::Rng& rng, Tensor* post_probs, Tensor* prior_probs_out) {
  const int n = static_cast<int>(prev.deter.dim(0));
  RssmState start = prev;
  bool any_first = false;
  for (float f : is_first.values()) any_first = any_first || f != 0.0f;
  if (any_first) {
    // Episode starts: the learned initial state replaces the carried one, the action is zero.
    Tensor keep = nn::rsub_scalar(1.0f, is_first);  // (n, 1)
    const RssmState init = initial(n);
    start.deter = nn::add(nn::mul(prev.deter, keep), nn::mul(init.deter, is_first));
    start.stoch = nn::add(nn::mul(prev.stoch, keep), nn::mul(init.stoch, is_first));
    action = nn::mul(action, keep);
  }
  // The prior's sample would go unused: only its probabilities, where asked for.
  Tensor deter = next_deter(start, action);
  if (prior_probs_out != nullptr) *prior_probs_out = prior_probs(deter);
  Tensor probs =
      nn::unimix_probs(post_head_(nn::concat({deter, embed}, -1)), config_.classes, config_.unimix);
  if (post_probs != nullptr) *post_probs = probs;
  return {deter, nn::sample_straight_through(probs, config_.classes, rng)};
}

bool WorldModel::acts_with(const std::string& param) {
  return param.starts_with("enc.") || param.starts_with("rssm.");
}

Tensor WorldModel::encode(Tensor images) { return encoder_(nn::add_scalar(images, -0.5f)); }

Tensor WorldModel::decode(Tensor features) { return nn::add_scalar(decoder_(features), 0.5f); }

Tensor WorldModel::cont_logits(Tensor features) { return cont_head_(features); }

Tensor WorldModel::reward_logits(Tensor features) { return reward_head_(features); }

Tensor WorldModel::features(const RssmState& state) {
  return nn::concat({state.deter, state.stoch}, -1);
}

Tensor WorldModel::batch_images(const SequenceBatch& batch) {
  const int b_size = batch.batch, t_size = batch.length;
  const std::size_t pixels = static_cast<std::size_t>(batch.height) * batch.width;
  Tensor images =
      nn::empty(Shape{static_cast<std::int64_t>(b_size) * t_size, batch.height, batch.width, 3});
  for (int t = 0; t < t_size; ++t) {
    for (int b = 0; b < b_size; ++b) {
      const std::size_t src = (static_cast<std::size_t>(b) * t_size + t) * pixels;
      const std::size_t dst = (static_cast<std::size_t>(t) * b_size + b) * pixels;
      class_ids_to_rgb(std::span(batch.frames).subspan(src, pixels),
                       images.values().subspan(3 * dst, 3 * pixels));
    }
  }
  return images;
}

Tensor WorldModel::time_major_column(const std::vector<float>& field, int batch, int length) {
  INDRIVE_CHECK_EQ(field.size(), static_cast<std::size_t>(batch) * length);
  Tensor out = nn::empty(Shape{static_cast<std::int64_t>(batch) * length, 1});
  for (std::size_t i = 0; i < field.size(); ++i) {
    out.data()[time_major_row(i, batch, length)] = field[i];
  }
  return out;
}

Tensor WorldModel::action_one_hot(const std::vector<int>& actions, int batch, int length) {
  INDRIVE_CHECK_EQ(actions.size(), static_cast<std::size_t>(batch) * length);
  std::vector<int> time_major(actions.size());
  for (int t = 0; t < length; ++t) {
    for (int b = 0; b < batch; ++b) time_major[t * batch + b] = actions[b * length + t];
  }
  return one_hot(time_major);
}

Tensor WorldModel::one_hot(const std::vector<int>& actions) {
  Tensor out = nn::zeros(Shape{static_cast<std::int64_t>(actions.size()), kNumActions});
  for (std::size_t i = 0; i < actions.size(); ++i) {
    INDRIVE_CHECK(actions[i] >= 0 && actions[i] < kNumActions) << "action " << actions[i];
    out.data()[i * kNumActions + actions[i]] = 1.0f;
  }
  return out;
}

WorldModelOutput WorldModel::observe(const SequenceBatch& batch, bool with_reward, nn::Rng& rng) {
  const int b_size = batch.batch, t_size = batch.length;
  INDRIVE_CHECK(batch.height == config_.image && batch.width == config_.image)
      << "batch frames " << batch.height << "x" << batch.width << " vs model image "
      << config_.image;
  const std::int64_t n = static_cast<std::int64_t>(b_size) * t_size;
  Tensor images = batch_images(batch);                                  // (N, H, W, 3)
  Tensor embed = encode(images);                                        // (N, E)
  Tensor is_first = time_major_column(batch.is_first, b_size, t_size);  // (N, 1)
  Tensor actions = action_one_hot(batch.actions, b_size, t_size);       // (N, 9)

  // Posterior rollout; the action that led to step t is the one taken at step t - 1.
  std::vector<Tensor> deters, stochs, posts;
  RssmState state = initial(b_size);
  Tensor prev_action = nn::zeros(Shape{b_size, kNumActions});
  for (int t = 0; t < t_size; ++t) {
    Tensor post;
    state = obs_step(state, prev_action, nn::slice(embed, t * b_size, (t + 1) * b_size, 0),
                     nn::slice(is_first, t * b_size, (t + 1) * b_size, 0), rng, &post);
    deters.push_back(state.deter);
    stochs.push_back(state.stoch);
    posts.push_back(post);
    prev_action = nn::slice(actions, t * b_size, (t + 1) * b_size, 0);
  }
  WorldModelOutput out;
  out.deter = nn::concat(deters, 0);
  out.stoch = nn::concat(stochs, 0);
  out.post_probs = nn::concat(posts, 0);
  // The prior at every step in one pass over all N rows: the loop needs only its h.
  const Tensor priors = prior_probs(out.deter);
  out.features = nn::concat({out.deter, out.stoch}, -1);

  // KL balancing with free bits on the KL summed over all latents.
  Tensor kl_dyn = nn::kl_categorical(nn::stop_gradient(out.post_probs), priors);  // (N)
  Tensor kl_rep = nn::kl_categorical(out.post_probs, nn::stop_gradient(priors));  // (N)
  Tensor dyn = nn::mean(nn::maximum(kl_dyn, config_.free_nats));
  Tensor rep = nn::mean(nn::maximum(kl_rep, config_.free_nats));
  // Reconstruction: squared error summed over pixels and channels, mean over the batch.
  Tensor recon = nn::scale(nn::sum(nn::squared_error(decode(out.features), images)),
                           1.0f / static_cast<float>(n));
  Tensor is_terminal = time_major_column(batch.is_terminal, b_size, t_size);
  out.cont_logits = cont_logits(out.features);
  Tensor cont = nn::mean(nn::bce_with_logits(out.cont_logits, nn::rsub_scalar(1.0f, is_terminal)));
  Tensor loss =
      nn::add(nn::scale(recon, config_.recon_scale),
              nn::add(nn::add(nn::scale(dyn, config_.kl_dyn), nn::scale(rep, config_.kl_rep)),
                      nn::scale(cont, config_.cont_scale)));
  if (with_reward) {
    INDRIVE_CHECK(!batch.rewards.empty()) << "reward loss requested on a reward-free batch";
    Tensor target = time_major_column(batch.rewards, b_size, t_size);
    Tensor reward =
        nn::mean(nn::twohot_cross_entropy(reward_logits(nn::stop_gradient(out.features)), target));
    loss = nn::add(loss, nn::scale(reward, config_.reward_scale));
    out.reward = reward.item();
  }
  out.loss = loss;
  out.recon = recon.item();
  out.dyn = dyn.item();
  out.rep = rep.item();
  out.kl = nn::mean(kl_rep).item();
  out.cont = cont.item();
  return out;
}

}  // namespace indrive::agent
