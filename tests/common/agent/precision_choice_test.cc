// Precision auto chooses by timing the agent's own update in both precisions, once per process
// and once per run (<run>/precision.txt, kept for a restarted learner on the same CPU); fp32 and
// bf16 are forced.
#include "indrive/agent/precision_choice.h"

#include <gtest/gtest.h>

#include <fstream>
#include <regex>
#include <string>

#include "child_process.h"
#include "indrive/agent/agent.h"
#include "indrive/nn/tensor.h"
#include "testing.h"

namespace indrive::agent {
namespace {

bool bf16_measurable() { return nn::bf16_supported() && nn::use_onednn(); }

// The rule, stated before any measurement: bf16 only where an update is at least 1.05x faster.
TEST(PrecisionChoice, Bf16OnlyWhereAnUpdateMeasuredClearlyFaster) {
  EXPECT_EQ(choose_by_update_time(1.543, 1.381), nn::Precision::kBf16);  // 1.12x
  EXPECT_EQ(choose_by_update_time(2.0, 3.0), nn::Precision::kFp32);      // bf16 slower
  EXPECT_EQ(choose_by_update_time(0.0370, 0.0365), nn::Precision::kFp32)
      << "1% is within two updates' noise";
  EXPECT_EQ(choose_by_update_time(1.05, 1.0), nn::Precision::kBf16);
  EXPECT_EQ(choose_by_update_time(1.0, 0.0), nn::Precision::kFp32) << "bf16 not measured";
  EXPECT_EQ(choose_by_update_time(1.2, 1.0, 1.5), nn::Precision::kFp32);
}

TEST(PrecisionChoice, Fp32AndBf16AreForcedWithoutMeasuring) {
  AgentConfig config = preset("tiny");
  config.precision = "fp32";
  const auto fp32 = known_precision(config);
  ASSERT_TRUE(fp32.has_value());
  EXPECT_EQ(fp32->precision, nn::Precision::kFp32);
  EXPECT_EQ(fp32->source, "forced");
  EXPECT_EQ(fp32->fp32_update_s, 0.0);
  EXPECT_EQ(fp32->describe(), "precision fp32 (forced by the config)");
  config.precision = "bf16";
  if (nn::bf16_supported()) {
    EXPECT_EQ(known_precision(config)->precision, nn::Precision::kBf16);
  } else {
    EXPECT_THROW(known_precision(config), AgentConfigError);
  }
}

SequenceBatch batch_of(const AgentConfig& c, int seed) {
  SequenceBatch b;
  b.batch = c.replay.batch, b.length = c.replay.length, b.height = b.width = c.world_model.image;
  const std::size_t n = static_cast<std::size_t>(b.batch) * b.length;
  b.frames.resize(n * b.height * b.width);
  for (std::size_t i = 0; i < b.frames.size(); ++i) b.frames[i] = (i * 7 + seed) % 8;
  b.actions.resize(n);
  for (std::size_t i = 0; i < n; ++i) b.actions[i] = static_cast<int>((i + seed) % 9);
  b.is_first.assign(n, 0.0f), b.is_last.assign(n, 0.0f), b.is_terminal.assign(n, 0.0f);
  for (int i = 0; i < b.batch; ++i) b.is_first[static_cast<std::size_t>(i) * b.length] = 1.0f;
  return b;
}

// An "auto" agent times its own update in both precisions, then is restored bitwise: it holds
// and trains exactly as an agent made with its chosen precision forced.
TEST(PrecisionChoice, AnAutoAgentMeasuresItselfAndIsRestoredBitwise) {
  nn::set_threads(1);
  AgentConfig config = preset("tiny");
  ASSERT_EQ(config.precision, "auto");
  config.replay.batch = 2, config.replay.length = 8;  // small, for a quick test
  Agent measured(config);
  const PrecisionChoice& first = measured.precision_choice();
  EXPECT_EQ(nn::precision(), first.precision);
  if (!bf16_measurable()) {
    EXPECT_EQ(first.precision, nn::Precision::kFp32);
    EXPECT_EQ(first.source, "no native bf16");
    return;
  }
  EXPECT_GT(first.fp32_update_s, 0.0);
  EXPECT_GT(first.bf16_update_s, 0.0);
  EXPECT_EQ(first.precision, choose_by_update_time(first.fp32_update_s, first.bf16_update_s))
      << first.describe();
  EXPECT_EQ(first.source.rfind("measured in ", 0), 0u) << first.source;
  EXPECT_NE(first.describe().find("s in bf16 against"), std::string::npos) << first.describe();
  std::printf("[figures] tiny (batch 2 x 8), 1 thread: %s\n", first.describe().c_str());
  EXPECT_EQ(measured.train_steps(), 0) << "the six timed updates are undone";

  AgentConfig forced = config;
  forced.precision = std::string(nn::to_string(first.precision));
  Agent fresh(forced);
  EXPECT_EQ(measured.checkpoint_bytes(), fresh.checkpoint_bytes());
  nn::set_precision(first.precision);
  const auto batch = batch_of(config, 3);
  EXPECT_EQ(measured.train_step(batch), fresh.train_step(batch)) << "the same update, bitwise";

  // A second agent of the model in this process takes the choice without measuring.
  const auto known = known_precision(config);
  ASSERT_TRUE(known.has_value());
  EXPECT_EQ(known->source, "measured earlier in this process");
  EXPECT_EQ(known->precision, first.precision);
  EXPECT_EQ(Agent(config).precision_choice().source, "measured earlier in this process");
}

TEST(PrecisionChoice, ARunKeepsItsMeasurementForARestartedLearnerOnTheSameCpu) {
  nn::set_threads(1);
  if (!bf16_measurable()) GTEST_SKIP() << "nothing is measured without native bf16";
  testing::TempDir dir;
  AgentConfig config = preset("tiny");
  config.replay.batch = 2, config.replay.length = 4;
  const Agent agent(config);
  const PrecisionChoice& first = agent.precision_choice();
  record_run_precision(config, first, dir.path());
  const auto file = dir.path() / "precision.txt";
  ASSERT_TRUE(std::filesystem::exists(file));
  const std::string text = testing::slurp(file);
  EXPECT_NE(text.find("chosen=" + std::string(nn::to_string(first.precision))), std::string::npos)
      << text;
  // A restarted learner takes the file's choice, whatever a new measurement would say: here
  // fp32, written over the first choice.
  const std::string edited =
      std::regex_replace(std::regex_replace(text, std::regex("chosen=[a-z0-9]+"), "chosen=fp32"),
                         std::regex("fp32_update_s=[^\n]+"), "fp32_update_s=0.123");
  std::ofstream(file) << edited;
  const auto again = run_precision(config, dir.path());
  ASSERT_TRUE(again.has_value());
  EXPECT_EQ(again->precision, nn::Precision::kFp32);
  EXPECT_NE(again->source.find("as measured at this run's start"), std::string::npos)
      << again->source;
  EXPECT_EQ(again->fp32_update_s, 0.123);
  // A choice read from the file is not written back.
  record_run_precision(config, *again, dir.path());
  EXPECT_EQ(testing::slurp(file), edited);
  // Measured for another CPU (a run moved to another machine): not taken.
  std::ofstream(file) << std::regex_replace(edited, std::regex("measured_for=[^\n]+"),
                                            "measured_for=another CPU | threads 1");
  const auto moved = run_precision(config, dir.path());
  ASSERT_TRUE(moved.has_value()) << "this process measured the model already";
  EXPECT_EQ(moved->source, "measured earlier in this process");
  // A forced precision is forced, file or not.
  AgentConfig forced = config;
  forced.precision = "bf16";
  EXPECT_EQ(run_precision(forced, dir.path())->source, "forced");
}

}  // namespace
}  // namespace indrive::agent
