// Tests of disagreement.cc, the latent disagreement (LD) ensemble: its reward, its chunked
// scoring and its one product for every member.
#include "indrive/agent/disagreement.h"

#include <gtest/gtest.h>

#include <cmath>

#include "indrive/nn/kernels.h"
#include "intrinsic_test_support.h"

namespace indrive::agent {
namespace {

using nn::Shape;
using nn::Tensor;
using namespace testing;

TEST(LatentDisagreement, RewardIsHigherOnPairsTheEnsembleWasNotTrainedOn) {
  nn::set_threads(1);
  nn::Rng rng(5);
  const WorldModelConfig model = preset("tiny").world_model;
  LatentDisagreement ld(small_intrinsic(Method::kDisag), model, rng);
  EXPECT_EQ(ld.members(), 8);
  float first = 0, last = 0;
  const auto [seen, unseen] = seen_vs_unseen(ld, model, 150, &first, &last);
  std::printf("LD loss %.3f -> %.3f, reward seen %.3g unseen %.3g\n", first, last, seen, unseen);
  EXPECT_LT(last, 0.5f * first);
  EXPECT_GT(unseen, 3.0f * seen);
}

TEST(LatentDisagreement, RewardIsTheScaledMeanVarianceAcrossMembers) {
  nn::Rng rng(6);
  const WorldModelConfig model = preset("tiny").world_model;
  IntrinsicConfig config = small_intrinsic(Method::kDisag);
  LatentDisagreement ld(config, model, rng);
  config.disag_reward = DisagReward::kStd;
  nn::Rng same(6);
  LatentDisagreement ld_std(config, model, same);  // same seed: the same members
  nn::current_graph().reset();
  Tensor feat = random_tensor(Shape{2, model.feat_dim()}, rng);
  Tensor action = WorldModel::one_hot({3, 7});
  const std::vector<float> var_reward = ld.reward(feat, action, feat);
  const std::vector<float> std_reward = ld_std.reward(feat, action, feat);
  // Recompute row 1 by hand from the members' predictions.
  Tensor input = nn::concat({feat, action}, -1);
  std::vector<Tensor> preds;
  for (int k = 0; k < 8; ++k) preds.push_back(ld.predict(k, input));
  const int s = model.stoch_dim();
  double var_sum = 0, std_sum = 0;
  for (int d = 0; d < s; ++d) {
    double mean = 0;
    for (const Tensor& p : preds) mean += p.data()[s + d] / 8.0;
    double var = 0;
    for (const Tensor& p : preds) var += std::pow(p.data()[s + d] - mean, 2) / 8.0;
    var_sum += var;
    std_sum += std::sqrt(var);
  }
  // The reward is the paper's formula times disag_scale; the raw mean is kept for metrics.
  const double scale = config.disag_scale;
  EXPECT_EQ(scale, 1e4);
  EXPECT_NEAR(var_reward[1], scale * var_sum / s, scale * 1e-7);
  EXPECT_NEAR(std_reward[1], scale * std_sum / s, scale * 1e-6);
  EXPECT_GT(var_reward[1], 0.0f);
  EXPECT_NEAR(ld_std.last_raw_reward(), (std_reward[0] + std_reward[1]) / (2 * scale), 1e-6);
  EXPECT_NEAR(ld_std.last_raw_std(), std::abs(std_reward[0] - std_reward[1]) / (2 * scale), 1e-6);
}

// Imagined states are scored in fixed chunks that run in parallel, each on its own thread and
// graph: the rewards are the same for one thread and two, bitwise, and a row of the last,
// partial chunk is the one computed from the members' own predictions.
TEST(LatentDisagreement, RewardsOverManyChunksDoNotDependOnTheThreadCount) {
  nn::Rng rng(16);
  const WorldModelConfig model = preset("tiny").world_model;
  LatentDisagreement ld(small_intrinsic(Method::kDisag), model, rng);
  nn::current_graph().reset();
  const int n = 3 * LatentDisagreement::kRewardChunkRows + 37;
  Tensor feat = random_tensor(Shape{n, model.feat_dim()}, rng);
  Tensor action = WorldModel::one_hot(random_actions(n, rng));
  const int threads = nn::threads();
  const std::size_t used0 = nn::current_graph().arena_used_bytes();
  nn::set_threads(1);
  const std::vector<float> one = ld.reward(feat, action, feat);
  const std::size_t used1 = nn::current_graph().arena_used_bytes();
  nn::set_threads(2);
  const std::vector<float> two = ld.reward(feat, action, feat);
  const std::size_t used2 = nn::current_graph().arena_used_bytes();
  nn::set_threads(threads);
  EXPECT_EQ(one, two);
  // Every chunk gave its memory back: a call keeps only the members' stacked first weights.
  const std::size_t stacked = sizeof(float) * (model.feat_dim() + kNumActions) * ld.members() *
                              small_intrinsic(Method::kDisag).units;
  EXPECT_GE(used1 - used0, stacked);
  EXPECT_LT(used1 - used0, stacked + 1024);  // and its node
  EXPECT_EQ(used2 - used1, used1 - used0);
  const int row = n - 5;
  Tensor input = nn::concat({nn::slice(feat, row, row + 1, 0), nn::slice(action, row, row + 1, 0)});
  const int s = model.stoch_dim();
  std::vector<Tensor> preds;
  for (int k = 0; k < ld.members(); ++k) preds.push_back(ld.predict(k, input));
  double var_sum = 0;
  for (int d = 0; d < s; ++d) {
    double mean = 0, var = 0;
    for (const Tensor& p : preds) mean += p.data()[d] / ld.members();
    for (const Tensor& p : preds) var += std::pow(p.data()[d] - mean, 2) / ld.members();
    var_sum += var;
  }
  const double expected = 1e4 * var_sum / s;
  EXPECT_GT(expected, 0.0);
  EXPECT_NEAR(one[row], expected, 1e-4 * expected);
}

// The K members' first products are made as one GEMM of their weights side by side: the loss
// and every gradient must be those of the members run one by one (fp32; the sums' order differs,
// so within float rounding, not bitwise).
TEST(LatentDisagreement, OneProductForEveryMemberGivesTheMembersOwnLossAndGradients) {
  const nn::Precision before = nn::precision();
  nn::set_precision(nn::Precision::kFp32);
  nn::Rng rng(9);
  const WorldModelConfig model = preset("tiny").world_model;
  LatentDisagreement ld(small_intrinsic(Method::kDisag), model, rng);
  const int n = 24;
  nn::current_graph().reset();
  const Tensor feat_t = random_tensor(Shape{n, model.feat_dim()}, rng);
  const Tensor post_t = random_latents(n, model, rng);
  const std::vector<float> feat(feat_t.values().begin(), feat_t.values().end());
  const std::vector<float> post(post_t.values().begin(), post_t.values().end());
  const std::vector<int> actions = random_actions(n, rng);
  // Each backward pass in a graph of its own, as in training.
  auto transitions = [&] {
    nn::current_graph().reset();
    Transitions tr;
    tr.feat = nn::constant(Shape{n, model.feat_dim()}, feat);
    tr.next_feat = tr.feat;
    tr.next_post = nn::constant(Shape{n, model.stoch_dim()}, post);
    tr.action = WorldModel::one_hot(actions);
    tr.mask = nn::full(Shape{n, 1}, 1.0f);
    return tr;
  };
  auto gradients = [&] {
    std::vector<std::vector<float>> grads;
    for (const auto& p : ld.params().params())
      grads.emplace_back(p->grad().begin(), p->grad().end());
    return grads;
  };

  Transitions tr = transitions();
  ld.params().zero_grad();
  Tensor fused_total = ld.loss(tr);
  const float fused_loss = fused_total.item();
  nn::current_graph().backward(fused_total);
  const auto fused = gradients();

  // The same loss member by member: cross-entropy of each member's softmax to the next
  // posterior, summed over latent groups, averaged over rows, summed over members.
  tr = transitions();
  ld.params().zero_grad();
  Tensor input = nn::concat({tr.feat, tr.action}, -1);
  Tensor total;
  for (int k = 0; k < ld.members(); ++k) {
    Tensor ce = nn::mul(tr.next_post, nn::log(ld.predict(k, input)));
    Tensor member_loss = nn::scale(nn::sum(ce), -1.0f / n);
    total = total.defined() ? nn::add(total, member_loss) : member_loss;
  }
  const float separate_loss = total.item();
  nn::current_graph().backward(total);
  const auto separate = gradients();

  EXPECT_NEAR(fused_loss, separate_loss, 1e-4f * std::abs(separate_loss));
  ASSERT_EQ(fused.size(), separate.size());
  int compared = 0;
  for (std::size_t i = 0; i < fused.size(); ++i) {
    double norm = 0;
    for (float g : separate[i]) norm = std::max(norm, static_cast<double>(std::abs(g)));
    for (std::size_t j = 0; j < fused[i].size(); ++j) {
      ASSERT_NEAR(fused[i][j], separate[i][j], 1e-4 * norm + 1e-7)
          << ld.params().params()[i]->name() << "[" << j << "]";
      ++compared;
    }
  }
  EXPECT_GT(compared, 100000) << "every member's parameters are compared";
  nn::set_precision(before);
}

}  // namespace
}  // namespace indrive::agent
