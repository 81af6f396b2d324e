// What the intrinsic modules' tests share: small configs, random inputs and latents, and the
// seen-versus-unseen check (a module trained on fixed transitions rewards unseen ones more).
#pragma once

#include <gtest/gtest.h>

#include <cmath>
#include <numeric>
#include <utility>
#include <vector>

#include "indrive/agent/intrinsic.h"
#include "indrive/agent/world_model.h"
#include "indrive/nn/nn.h"

namespace indrive::agent::testing {

using nn::Shape;
using nn::Tensor;

inline IntrinsicConfig small_intrinsic(Method method) {
  IntrinsicConfig c;
  c.method = method;
  c.units = 64;
  c.rnd_embed = 32;
  c.lr = 1e-3f;
  return c;
}

inline Tensor random_tensor(const Shape& shape, nn::Rng& rng, float offset = 0.0f) {
  Tensor t = nn::empty(shape);
  for (float& v : t.values()) v = rng.normal() + offset;
  return t;
}

inline std::vector<int> random_actions(int n, nn::Rng& rng) {
  std::vector<int> a(n);
  for (int& x : a) x = static_cast<int>(rng.below(kNumActions));
  return a;
}

// Random next-latent targets: one-hot per group (a posterior sample), (n, S).
inline Tensor random_latents(int n, const WorldModelConfig& model, nn::Rng& rng) {
  Tensor t = nn::zeros(Shape{n, model.stoch_dim()});
  for (int i = 0; i < n * model.stoch; ++i)
    t.data()[i * model.classes + rng.below(model.classes)] = 1;
  return t;
}

inline float mean_of(const std::vector<float>& v) {
  return std::accumulate(v.begin(), v.end(), 0.0f) / static_cast<float>(v.size());
}

// Trains `module` on fixed transitions, then returns the rewards on the trained pairs and on
// unseen pairs (shifted inputs), computed in one call so normalisers treat them alike.
inline std::pair<float, float> seen_vs_unseen(IntrinsicModule& module,
                                              const WorldModelConfig& model, int steps,
                                              float* first_loss, float* last_loss) {
  nn::Rng data_rng(11);
  const int n = 64;
  std::vector<float> feat(n * model.feat_dim()), next(n * model.feat_dim()), post;
  for (float& v : feat) v = data_rng.normal();
  for (float& v : next) v = data_rng.normal();
  nn::current_graph().reset();
  Tensor post_t = random_latents(n, model, data_rng);
  post.assign(post_t.values().begin(), post_t.values().end());
  const std::vector<int> actions = random_actions(n, data_rng);
  for (int i = 0; i < steps; ++i) {
    nn::current_graph().reset();
    Transitions tr;
    tr.feat = nn::constant(Shape{n, model.feat_dim()}, feat);
    tr.next_feat = nn::constant(Shape{n, model.feat_dim()}, next);
    tr.next_post = nn::constant(Shape{n, model.stoch_dim()}, post);
    tr.action = WorldModel::one_hot(actions);
    tr.mask = nn::full(Shape{n, 1}, 1.0f);
    Tensor loss = module.loss(tr);
    if (i == 0) *first_loss = loss.item();
    *last_loss = loss.item();
    nn::current_graph().backward(loss);
    module.step();
  }
  nn::current_graph().reset();
  Tensor seen = nn::constant(Shape{n, model.feat_dim()}, feat);
  Tensor seen_next = nn::constant(Shape{n, model.feat_dim()}, next);
  Tensor unseen = random_tensor(Shape{n, model.feat_dim()}, data_rng, 1.5f);
  Tensor unseen_next = random_tensor(Shape{n, model.feat_dim()}, data_rng, 1.5f);
  const std::vector<int> unseen_actions = random_actions(n, data_rng);
  std::vector<int> all_actions = actions;
  all_actions.insert(all_actions.end(), unseen_actions.begin(), unseen_actions.end());
  const std::vector<float> r =
      module.reward(nn::concat({seen, unseen}, 0), WorldModel::one_hot(all_actions),
                    nn::concat({seen_next, unseen_next}, 0));
  const std::vector<float> r_seen(r.begin(), r.begin() + n), r_unseen(r.begin() + n, r.end());
  for (float x : r) EXPECT_TRUE(std::isfinite(x));
  return {mean_of(r_seen), mean_of(r_unseen)};
}

}  // namespace indrive::agent::testing
