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
  const PrecisionChoice fp32 = choose_precision(config);
  EXPECT_EQ(fp32.precision, nn::Precision::kFp32);
  EXPECT_EQ(fp32.source, "forced");
  EXPECT_EQ(fp32.fp32_update_s, 0.0);
  EXPECT_EQ(fp32.describe(), "precision fp32 (forced by the config)");
  config.precision = "bf16";
  if (nn::bf16_supported()) {
    EXPECT_EQ(choose_precision(config).precision, nn::Precision::kBf16);
  } else {
    EXPECT_THROW(choose_precision(config), AgentConfigError);
  }
}

TEST(PrecisionChoice, AutoTimesTheUpdateOncePerProcessAndTheAgentRunsItsChoice) {
  nn::set_threads(1);
  AgentConfig config = preset("tiny");
  ASSERT_EQ(config.precision, "auto");
  config.replay.batch = 2, config.replay.length = 8;  // small, for a quick test
  nn::set_precision(nn::Precision::kFp32);
  const PrecisionChoice first = choose_precision(config);
  EXPECT_EQ(nn::precision(), nn::Precision::kFp32) << "measuring leaves the precision as it was";
  const PrecisionChoice second = choose_precision(config);
  EXPECT_EQ(first.precision, second.precision);
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
  EXPECT_EQ(second.source, "measured earlier in this process");
  EXPECT_EQ(second.bf16_update_s, first.bf16_update_s);
  EXPECT_NE(first.describe().find("s in bf16 against"), std::string::npos) << first.describe();
  std::printf("[figures] tiny (batch 2 x 8), 1 thread: %s\n", first.describe().c_str());
  const Agent agent(config);
  EXPECT_EQ(agent.precision_choice().source, "measured earlier in this process");
  EXPECT_EQ(nn::precision(), first.precision);
}

TEST(PrecisionChoice, ARunKeepsItsFirstMeasurementOnTheSameCpu) {
  nn::set_threads(1);
  testing::TempDir dir;
  AgentConfig config = preset("tiny");
  config.replay.batch = 2, config.replay.length = 8;
  const PrecisionChoice first = choose_precision(config, dir.path());
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
  const PrecisionChoice again = choose_precision(config, dir.path());
  EXPECT_EQ(again.precision, nn::Precision::kFp32);
  EXPECT_NE(again.source.find("as measured at this run's start"), std::string::npos)
      << again.source;
  EXPECT_EQ(again.fp32_update_s, 0.123);
  // Measured for another CPU (a run moved to another machine): measured again, file rewritten.
  std::ofstream(file) << std::regex_replace(edited, std::regex("measured_for=[^\n]+"),
                                            "measured_for=another CPU | threads 1");
  const PrecisionChoice moved = choose_precision(config, dir.path());
  EXPECT_EQ(moved.source.find("as measured at this run's start"), std::string::npos);
  EXPECT_EQ(moved.precision, first.precision);
  EXPECT_NE(testing::slurp(file).find("chosen=" + std::string(nn::to_string(first.precision))),
            std::string::npos);
  // A forced precision neither reads nor writes the file.
  std::filesystem::remove(file);
  AgentConfig forced = config;
  forced.precision = "fp32";
  EXPECT_EQ(choose_precision(forced, dir.path()).source, "forced");
  EXPECT_FALSE(std::filesystem::exists(file));
}

}  // namespace
}  // namespace indrive::agent
