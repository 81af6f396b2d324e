#include "indrive/agent/agent.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>
#include <iterator>
#include <numeric>

#include "agent_test_support.h"
#include "dot_env.h"
#include "indrive/agent/policy.h"
#include "indrive/basics/checksum.h"
#include "testing.h"

namespace indrive::agent {
namespace {

using namespace test_support;  // tiny_config, dot_replay, values_named, ...

std::vector<float> values_of(const nn::ParamGroup& g) {
  std::vector<float> out;
  for (const auto& p : g.params()) out.insert(out.end(), p->value().begin(), p->value().end());
  return out;
}

bool all_finite(const TrainMetrics& m) {
  for (const auto& [name, value] : m)
    if (!std::isfinite(value)) return false;
  return true;
}

float metric(const TrainMetrics& m, const std::string& name) {
  for (const auto& [key, value] : m)
    if (key == name) return value;
  ADD_FAILURE() << "no metric " << name;
  return NAN;
}

TEST(Agent, PretrainStepsWithEachMethodAreFiniteAndRewardFree) {
  nn::set_threads(1);
  ReplayBuffer replay = dot_replay(false);
  for (Method method : {Method::kDisag, Method::kIcm, Method::kRnd}) {
    Agent agent(tiny_config(Phase::kPretrain, method));
    const SequenceBatch batch = replay.sample(2, 8);
    ASSERT_TRUE(batch.rewards.empty());
    const TrainMetrics m = agent.train_step(batch);
    EXPECT_TRUE(all_finite(m)) << to_string(method);
    for (const auto& [name, value] : m) EXPECT_EQ(name.find("reward") == 0, false);
    EXPECT_TRUE(std::isfinite(metric(m, "expl/reward")));
    EXPECT_EQ(agent.train_steps(), 1);
  }
}

TEST(Agent, StageTimingCoversTheStagesThatRunInEachPhase) {
  nn::set_threads(1);
  ReplayBuffer with = dot_replay(true, 60), without = dot_replay(false, 60);
  Agent pretrain(tiny_config(Phase::kPretrain));
  EXPECT_EQ(pretrain.last_timing().total(), 0.0);  // nothing measured before the first step
  pretrain.train_step(without.sample(2, 8));
  const StepTiming p = pretrain.last_timing();
  for (double s : {p.world_model, p.intrinsic, p.imagine, p.reward, p.behavior, p.backward})
    EXPECT_GT(s, 0.0);
  EXPECT_GE(p.optimizers, 0.0);
  const TrainMetrics m = p.as_metrics();
  ASSERT_EQ(m.size(), 8u);
  EXPECT_EQ(m.back().first, "time/update_s");
  EXPECT_FLOAT_EQ(m.back().second, static_cast<float>(p.total()));
  EXPECT_FLOAT_EQ(metric(m, "time/reward_s"), static_cast<float>(p.reward));

  // Fine-tuning trains no intrinsic module: its stage is not run, and is zero.
  Agent finetune(tiny_config(Phase::kFinetune));
  finetune.train_step(with.sample(2, 8));
  EXPECT_EQ(finetune.last_timing().intrinsic, 0.0);
  EXPECT_GT(finetune.last_timing().world_model, 0.0);
}

TEST(Agent, RejectsRewardsInPretrainingAndTheirAbsenceInTaskPhases) {
  ReplayBuffer with = dot_replay(true, 60), without = dot_replay(false, 60);
  Agent pretrain(tiny_config(Phase::kPretrain));
  EXPECT_THROW(pretrain.train_step(with.sample(1, 4)), AgentError);
  Agent dreamer(tiny_config(Phase::kDreamer));
  EXPECT_THROW(dreamer.train_step(without.sample(1, 4)), AgentError);
}

TEST(Agent, FinetuneLeavesFrozenPartsBitwiseUnchanged) {
  nn::set_threads(1);
  indrive::testing::TempDir dir;
  {
    // A pretrained checkpoint whose optimisers hold nonzero moments.
    Agent pretrain(tiny_config(Phase::kPretrain));
    ReplayBuffer replay = dot_replay(false);
    for (int i = 0; i < 2; ++i) pretrain.train_step(replay.sample(2, 8));
    pretrain.save_checkpoint(dir.path() / "pretrain.ckpt");
  }
  Agent agent(tiny_config(Phase::kFinetune));
  agent.load_checkpoint(dir.path() / "pretrain.ckpt");
  // The task actor starts as the pretrained exploration actor.
  EXPECT_EQ(values_of(agent.task().actor_params()), values_of(agent.exploration().actor_params()));
  const auto wm = values_of(agent.world_model().params());
  const auto intrinsic = values_of(agent.intrinsic().params());
  const auto expl_actor = values_of(agent.exploration().actor_params());
  const auto expl_critic = values_of(agent.exploration().critic_params());
  const auto reward = values_of(agent.world_model().reward_params());
  const auto task_actor = values_of(agent.task().actor_params());
  const auto task_critic = values_of(agent.task().critic_params());
  ReplayBuffer replay = dot_replay(true);
  for (int i = 0; i < 2; ++i) {
    const TrainMetrics m = agent.train_step(replay.sample(2, 8));
    EXPECT_TRUE(all_finite(m));
  }
  EXPECT_EQ(values_of(agent.world_model().params()), wm);
  EXPECT_EQ(values_of(agent.intrinsic().params()), intrinsic);
  EXPECT_EQ(values_of(agent.exploration().actor_params()), expl_actor);
  EXPECT_EQ(values_of(agent.exploration().critic_params()), expl_critic);
  EXPECT_NE(values_of(agent.world_model().reward_params()), reward);
  EXPECT_NE(values_of(agent.task().actor_params()), task_actor);
  EXPECT_NE(values_of(agent.task().critic_params()), task_critic);
}

// agent.finetune_cont: few-shot trains the continuation head, and nothing else of the world
// model, towards the task's terminal steps; off (the paper's frozen world model), the head
// only reports what it predicts there.
TEST(Agent, FinetuneContTrainsOnlyTheContinuationHead) {
  nn::set_threads(1);
  ReplayBuffer replay = dot_replay_with_terminals();
  const SequenceBatch batch = replay.sample(4, 10);
  ASSERT_GT(std::count(batch.is_terminal.begin(), batch.is_terminal.end(), 1.0f), 0);
  for (const bool train_cont : {false, true}) {
    AgentConfig config = tiny_config(Phase::kFinetune);
    config.finetune_cont = train_cont;
    config.world_model.lr = 1e-3f;
    Agent agent(config);
    const auto body = values_named(agent.world_model().params(), false);
    const auto head = values_named(agent.world_model().params(), true);
    std::vector<float> cont_loss, at_terminal;
    for (int i = 0; i < 30; ++i) {
      const TrainMetrics m = agent.train_step(batch);
      cont_loss.push_back(metric(m, "wm/cont"));
      at_terminal.push_back(metric(m, "wm/cont_at_terminal"));
      EXPECT_TRUE(at_terminal.back() > 0.0f && at_terminal.back() < 1.0f) << at_terminal.back();
    }
    EXPECT_EQ(values_named(agent.world_model().params(), false), body);
    // Means of the first and last 10 updates: each loss is of one posterior sample of the
    // batch, which moves it by about 10% from update to update even with the head frozen.
    const auto mean10 = [](auto first) { return std::accumulate(first, first + 10, 0.0f) / 10; };
    const float before = mean10(cont_loss.begin()), after = mean10(cont_loss.end() - 10);
    if (train_cont) {
      EXPECT_NE(values_named(agent.world_model().params(), true), head);
      // It fits the batch's continuation targets (terminal steps included).
      EXPECT_LT(after, 0.7f * before) << before << " -> " << after;
    } else {
      EXPECT_EQ(values_named(agent.world_model().params(), true), head);
      EXPECT_NEAR(after, before, 0.1f * before);
    }
  }
}

// agent.finetune_world_model: few-shot trains the whole world model on the task's replay (its
// reconstruction falls), the continuation head with it, and the intrinsic module stays frozen;
// the terminal-step diagnostic is logged either way.
TEST(Agent, FinetuneWorldModelTrainsTheWholeModel) {
  nn::set_threads(1);
  ReplayBuffer replay = dot_replay_with_terminals();
  const SequenceBatch batch = replay.sample(4, 10);
  AgentConfig config = tiny_config(Phase::kFinetune);
  config.finetune_world_model = true;
  config.world_model.lr = 1e-3f;
  Agent agent(config);
  const auto body = values_named(agent.world_model().params(), false);
  const auto head = values_named(agent.world_model().params(), true);
  const auto intrinsic = values_of(agent.intrinsic().params());
  std::vector<float> recon;
  for (int i = 0; i < 30; ++i) {
    const TrainMetrics m = agent.train_step(batch);
    recon.push_back(metric(m, "wm/recon"));
    const float at_terminal = metric(m, "wm/cont_at_terminal");
    EXPECT_TRUE(at_terminal > 0.0f && at_terminal < 1.0f) << at_terminal;
    EXPECT_GT(metric(m, "wm/grad_norm"), 0.0f);
  }
  EXPECT_NE(values_named(agent.world_model().params(), false), body);
  EXPECT_NE(values_named(agent.world_model().params(), true), head);
  EXPECT_EQ(values_of(agent.intrinsic().params()), intrinsic);
  EXPECT_LT(recon.back(), 0.7f * recon.front()) << recon.front() << " -> " << recon.back();
}

TEST(Agent, DreamerTrainsTheWorldModelAndRewardHead) {
  nn::set_threads(1);
  Agent agent(tiny_config(Phase::kDreamer));
  const auto wm = values_of(agent.world_model().params());
  const auto reward = values_of(agent.world_model().reward_params());
  const auto intrinsic = values_of(agent.intrinsic().params());
  ReplayBuffer replay = dot_replay(true);
  const TrainMetrics m = agent.train_step(replay.sample(2, 8));
  EXPECT_TRUE(all_finite(m));
  EXPECT_TRUE(std::isfinite(metric(m, "wm/reward")));
  EXPECT_NE(values_of(agent.world_model().params()), wm);
  EXPECT_NE(values_of(agent.world_model().reward_params()), reward);
  EXPECT_EQ(values_of(agent.intrinsic().params()), intrinsic);
}

// Two updates in each phase with 1 and 2 threads, the backward's parts side by side or op by
// op: the update's parallel pieces (the backward pass's independent parts with their optimiser
// steps, or its ops, and the ensemble's reward chunks) leave every parameter as one thread
// doing one backward of the summed losses does, bitwise.
TEST(Agent, UpdatesWithTwoThreadsGiveBitwiseTheParametersOfOne) {
  for (const Phase phase : {Phase::kPretrain, Phase::kFinetune, Phase::kDreamer}) {
    ReplayBuffer replay = dot_replay(phase != Phase::kPretrain);
    const SequenceBatch b1 = replay.sample(2, 8), b2 = replay.sample(2, 8);
    std::vector<std::vector<float>> params;
    const std::pair<int, bool> schedules[] = {{1, false}, {1, true}, {2, true}, {2, false}};
    for (const auto& [threads, parts] : schedules) {
      nn::set_threads(threads);
      AgentConfig config = tiny_config(phase);
      config.backward_parts = parts;
      Agent agent(config);
      agent.train_step(b1);
      agent.train_step(b2);
      params.emplace_back();
      for (nn::ParamGroup* g : agent.groups()) {
        const std::vector<float> v = values_of(*g);
        params.back().insert(params.back().end(), v.begin(), v.end());
      }
    }
    nn::set_threads(1);
    for (std::size_t i = 1; i < params.size(); ++i) {
      ASSERT_EQ(params[0].size(), params[i].size());
      EXPECT_EQ(std::memcmp(params[0].data(), params[i].data(), params[0].size() * sizeof(float)),
                0)
          << to_string(phase) << ", " << schedules[i].first << " threads, "
          << (schedules[i].second ? "parts side by side" : "op by op");
    }
  }
}

TEST(Policy, ActsFromSnapshotBytesOnly) {
  nn::set_threads(1);
  Agent agent(tiny_config());
  ReplayBuffer replay = dot_replay(false);
  agent.train_step(replay.sample(2, 8));
  Policy policy(tiny_config());
  policy.load_snapshot(agent.snapshot());
  synthetic::DotEnv env(32, 1);
  PolicyState state;
  std::vector<std::uint8_t> frame = env.reset();
  for (int t = 0; t < 5; ++t) {
    const int a = policy.act(frame, t == 0, state, true);
    ASSERT_GE(a, 0);
    ASSERT_LT(a, kNumActions);
    float total = 0;
    for (float p : policy.last_probs()) total += p;
    EXPECT_NEAR(total, 1.0f, 1e-5);
    EXPECT_EQ(state.deter.size(), 128u);
    env.step(a);
    frame = env.frame();
  }
  // The snapshot's actor is the one that acts: on the posterior state that act() returns,
  // the agent's exploration actor gives the same probabilities, and mode acting takes the max.
  PolicyState fresh;
  const int mode = policy.act(frame, true, fresh, false);
  const std::vector<float> policy_probs = policy.last_probs();
  nn::current_graph().reset();
  nn::Tensor feat = nn::concat(
      {nn::constant(nn::Shape{1, 128}, fresh.deter), nn::constant(nn::Shape{1, 256}, fresh.stoch)});
  nn::Tensor probs = agent.exploration().action_probs(feat);
  for (int a = 0; a < kNumActions; ++a) {
    EXPECT_NEAR(probs.data()[a], policy_probs[a], 1e-6);
    EXPECT_LE(policy_probs[a], policy_probs[mode]);
  }
  // Snapshots of another size are rejected.
  AgentConfig bigger = tiny_config();
  bigger.world_model.deter = 64;
  Policy mismatched(bigger);
  EXPECT_THROW(mismatched.load_snapshot(agent.snapshot()), nn::SerializationError);
}

// Snapshots carry what acting runs: no decoder, no continuation head; a policy acts the same
// from such a snapshot as from one of the whole world model (the form written before), which
// still loads.
TEST(Policy, SnapshotsLeaveOutWhatActingDoesNotRunAndOldWholeOnesStillLoad) {
  nn::set_threads(1);
  Agent agent(tiny_config());
  ReplayBuffer replay = dot_replay(false);
  agent.train_step(replay.sample(2, 8));
  const std::vector<std::uint8_t> snapshot = agent.snapshot();
  std::int64_t acting = 0, world_model = 0;
  for (const nn::BlobGroup& group : nn::blob_contents(snapshot)) {
    for (const nn::BlobParam& param : group.params) {
      EXPECT_FALSE(param.name.starts_with("dec.") || param.name.starts_with("cont."))
          << group.name << "/" << param.name;
      if (group.name == "world_model") acting += param.shape.numel();
    }
  }
  for (const auto& param : agent.world_model().params().params()) world_model += param->numel();
  // tiny: encoder and RSSM are 309k of the world model's 583k parameters.
  EXPECT_LT(acting, world_model * 6 / 10) << acting << " of " << world_model;

  AgentConfig config = tiny_config();
  config.eval_sample = false;
  Policy slim(config), whole(config);
  slim.load_snapshot(snapshot);
  const nn::ParamGroup* parts[2] = {&agent.world_model().params(),
                                    &agent.exploration().actor_params()};
  whole.load_snapshot(nn::save_params(std::span<const nn::ParamGroup* const>(parts, 2)));
  synthetic::DotEnv env(32, 3);
  PolicyState a, b;
  std::vector<std::uint8_t> frame = env.reset();
  for (int t = 0; t < 10; ++t) {
    const int action = slim.act(frame, t == 0, a, true);
    ASSERT_EQ(whole.act(frame, t == 0, b, true), action) << "step " << t;
    ASSERT_EQ(slim.last_probs(), whole.last_probs()) << "step " << t;
    env.step(action);
    frame = env.frame();
  }
  // A snapshot of another size is still refused, with the current form's message.
  AgentConfig bigger = tiny_config();
  bigger.world_model.deter = 64;
  Policy mismatched(bigger);
  try {
    mismatched.load_snapshot(snapshot);
    ADD_FAILURE() << "a snapshot of another size loaded";
  } catch (const nn::SerializationError& error) {
    EXPECT_NE(std::string(error.what()).find("rssm."), std::string::npos) << error.what();
  }
}

TEST(Policy, ActsWithTheActorOfItsPhase) {
  nn::set_threads(1);
  Agent agent(tiny_config(Phase::kFinetune));
  EXPECT_EQ(agent.acting_actor_group(), "task_actor");
  EXPECT_TRUE(agent.config().eval_sample);  // DreamerV3 evaluates with sampled actions
  AgentConfig mode_config = tiny_config(Phase::kFinetune);
  mode_config.eval_sample = false;
  Policy task_policy(mode_config);
  task_policy.load_snapshot(agent.snapshot());
  // A pretraining policy expects the exploration actor and refuses a task snapshot.
  Policy expl_policy(tiny_config(Phase::kPretrain));
  EXPECT_THROW(expl_policy.load_snapshot(agent.snapshot()), nn::SerializationError);
  // Evaluation acting without sampling takes the most likely action.
  synthetic::DotEnv env(32, 2);
  PolicyState state;
  const int action = task_policy.act_eval(env.reset(), true, state);
  const std::vector<float>& probs = task_policy.last_probs();
  for (float p : probs) EXPECT_LE(p, probs[action]);
}

// Sampled evaluation is reproducible per episode: after reseed(seed) a policy acts the same
// whatever it did before, so evaluators that split a grid differently agree episode by episode.
TEST(Policy, ReseedMakesSampledActingIndependentOfWhatRanBefore) {
  Agent agent(tiny_config(Phase::kFinetune));
  AgentConfig config = tiny_config(Phase::kFinetune);
  ASSERT_TRUE(config.eval_sample);
  Policy fresh(config), used(config);
  fresh.load_snapshot(agent.snapshot());
  used.load_snapshot(agent.snapshot());
  synthetic::DotEnv env(32, 2);
  std::vector<std::vector<std::uint8_t>> frames;
  frames.push_back(env.reset());
  for (int t = 0; t < 30; ++t) {
    env.step(t % kNumActions);
    frames.push_back(env.frame());
  }
  PolicyState warmup;  // an earlier "episode" on the second policy only
  for (int t = 0; t < 10; ++t) used.act_eval(frames[t], t == 0, warmup);

  auto episode = [&](Policy& p, std::uint64_t seed) {
    p.reseed(seed);
    PolicyState state;
    std::vector<int> actions;
    for (std::size_t t = 0; t < frames.size(); ++t)
      actions.push_back(p.act_eval(frames[t], t == 0, state));
    return actions;
  };
  const std::vector<int> a = episode(fresh, 7), b = episode(used, 7);
  EXPECT_EQ(a, b);
  // Another seed gives another sample path (31 sampled actions from a near-uniform actor).
  EXPECT_NE(episode(fresh, 8), a);
}

TEST(Policy, RandomPolicyCoversAllActions) {
  RandomPolicy random(3);
  std::vector<int> counts(kNumActions, 0);
  for (int i = 0; i < 9000; ++i) counts[random.act()]++;
  for (int c : counts) EXPECT_NEAR(c, 1000, 150);
}

}  // namespace
}  // namespace indrive::agent
