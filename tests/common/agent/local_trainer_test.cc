#include "indrive/agent/local_trainer.h"

#include <gtest/gtest.h>

#include <atomic>
#include <cmath>

#include "dot_env.h"
#include "testing.h"

namespace indrive::agent {
namespace {

// The dot environment behind the trainer's interface.
class DotEnvironment : public Environment {
 public:
  explicit DotEnvironment(std::uint64_t seed) : env_(32, seed, 12) {}
  EnvStep reset() override { return {env_.reset(), 0.0f, false, false}; }
  EnvStep step(int action) override {
    const float reward = env_.step(action);
    return {env_.frame(), reward, env_.done(), false};
  }

 private:
  synthetic::DotEnv env_;
};

AgentConfig loop_config(Phase phase) {
  AgentConfig c = preset("tiny");
  c.phase = phase;
  c.replay.batch = 4;
  c.replay.length = 8;
  c.replay.prefill = 40;
  c.behavior.horizon = 5;
  c.seed = 3;
  c.precision = "fp32";  // resumes are compared bitwise; "auto" may measure each differently
  return c;
}

TEST(LocalTrainer, PretrainThenFinetuneInOneProcess) {
  nn::set_threads(1);
  indrive::testing::TempDir dir;
  DotEnvironment env(1);
  std::vector<TrainMetrics> history;
  {
    LocalTrainer trainer(loop_config(Phase::kPretrain), env, {.train_ratio = 8});
    trainer.run(160, [&](const TrainMetrics& m) { history.push_back(m); });
    const LocalTrainerCounters& c = trainer.counters();
    EXPECT_EQ(c.env_steps, 160);
    EXPECT_GT(c.episodes, 10);
    // 8 replayed steps per env step, 32 per update: one update per 4 env steps after prefill.
    EXPECT_EQ(c.updates, 160 * 8 / 32);
    EXPECT_FALSE(trainer.replay().options().has_rewards);
    for (const TrainMetrics& m : history) {
      for (const auto& [name, value] : m) ASSERT_TRUE(std::isfinite(value)) << name;
    }
    trainer.save(dir.path());
  }
  // A finetune trainer starts from the pretrained checkpoint with a reward-keeping replay.
  LocalTrainer finetune(loop_config(Phase::kFinetune), env, {.train_ratio = 8});
  finetune.load(dir.path());
  EXPECT_EQ(finetune.agent().train_steps(), static_cast<std::int64_t>(history.size()));
  EXPECT_TRUE(finetune.replay().options().has_rewards);
  EXPECT_EQ(finetune.replay().size(), 0);  // the reward-free pretraining replay is not reused
  const auto wm_before = finetune.agent().world_model().params().params()[0]->value();
  const std::vector<float> wm_copy(wm_before.begin(), wm_before.end());
  int finetune_updates = 0;
  finetune.run(80, [&](const TrainMetrics& m) {
    ++finetune_updates;
    for (const auto& [name, value] : m) ASSERT_TRUE(std::isfinite(value)) << name;
  });
  EXPECT_GT(finetune_updates, 0);
  const auto wm_after = finetune.agent().world_model().params().params()[0]->value();
  EXPECT_TRUE(std::equal(wm_copy.begin(), wm_copy.end(), wm_after.begin()));
}

TEST(LocalTrainer, ResumesFromItsCheckpointFolder) {
  nn::set_threads(1);
  indrive::testing::TempDir dir;
  DotEnvironment env(2);
  LocalTrainer a(loop_config(Phase::kPretrain), env, {.train_ratio = 8});
  a.run(80);
  a.save(dir.path());
  DotEnvironment env2(2);
  LocalTrainer b(loop_config(Phase::kPretrain), env2, {.train_ratio = 8});
  b.load(dir.path());
  EXPECT_EQ(b.agent().train_steps(), a.agent().train_steps());
  EXPECT_EQ(b.replay().size(), a.replay().size());
  // Corrupt folder contents are reported, not crashed on.
  EXPECT_THROW(b.load(dir.path() / "missing"), AgentError);
}

// A stop request is honoured between two updates: the catch-up after the prefill (10 updates
// owed at once here) does not hold a SIGTERM for its whole length. The updates still owed are
// trained by the next call.
TEST(LocalTrainer, StopsBetweenUpdatesAndTrainsWhatIsOwedLater) {
  nn::set_threads(1);
  DotEnvironment env(4);
  LocalTrainer trainer(loop_config(Phase::kPretrain), env, {.train_ratio = 8});
  std::atomic<bool> stop{false};
  trainer.run(
      100, [&](const TrainMetrics&) { stop = true; }, &stop);
  // Prefill 40, then the 41st step owes 41 * 8 / 32 = 10 updates; the first one stops it.
  EXPECT_EQ(trainer.counters().env_steps, 41);
  EXPECT_EQ(trainer.counters().updates, 1);
  stop = false;
  trainer.run(1, nullptr, &stop);
  EXPECT_EQ(trainer.counters().env_steps, 42);
  EXPECT_EQ(trainer.counters().updates, 42 * 8 / 32);

  // A resumed run's trainer keeps the ratio over the whole run: what an earlier session (41
  // steps, 1 update) still owed is trained with this session's once its prefill is done.
  DotEnvironment env2(4);
  LocalTrainer resumed(loop_config(Phase::kPretrain), env2, {.train_ratio = 8});
  resumed.continue_from(41, 1);
  resumed.run(41);
  EXPECT_EQ(resumed.counters().updates, (41 + 41) * 8 / 32 - 1);
}

}  // namespace
}  // namespace indrive::agent
