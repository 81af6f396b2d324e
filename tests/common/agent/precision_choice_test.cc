// Precision auto chooses by measuring the model's own products, once per process and once per
// run (<run>/precision.txt, kept for a restarted learner on the same CPU); fp32 and bf16 are
// forced.
#include "indrive/agent/precision_choice.h"

#include <gtest/gtest.h>

#include <fstream>
#include <regex>
#include <string>

#include "indrive/agent/agent.h"
#include "indrive/nn/tensor.h"
#include "child_process.h"
#include "testing.h"

namespace indrive::agent {
namespace {

bool bf16_measurable() { return nn::bf16_supported() && nn::use_onednn(); }

TEST(PrecisionChoice, ProductShapesFollowTheModelsSizes) {
  AgentConfig config = preset("tiny");
  const auto shapes = product_shapes(config);
  ASSERT_EQ(shapes.size(), 21u) << "7 layers, each forward and two backward products";
  const std::int64_t rows = static_cast<std::int64_t>(config.replay.batch) * config.replay.length;
  // The GRU's gates: (rows, units + deter) x (units + deter, 3 deter), then its backward.
  const auto& w = config.world_model;
  EXPECT_EQ(shapes[9].m, rows);
  EXPECT_EQ(shapes[9].k, w.units + w.deter);
  EXPECT_EQ(shapes[9].n, 3 * w.deter);
  EXPECT_EQ(shapes[10].k, 3 * w.deter) << "the input's gradient";
  EXPECT_EQ(shapes[11].m, w.units + w.deter) << "the weights' gradient";
  const int deter = w.deter;
  config.world_model.deter *= 2;
  EXPECT_EQ(product_shapes(config)[9].n, 6 * deter);
}

TEST(PrecisionChoice, Fp32AndBf16AreForcedWithoutMeasuring) {
  AgentConfig config = preset("tiny");
  config.precision = "fp32";
  const PrecisionChoice fp32 = choose_precision(config);
  EXPECT_EQ(fp32.precision, nn::Precision::kFp32);
  EXPECT_EQ(fp32.source, "forced");
  EXPECT_EQ(fp32.rates.fp32_gflops, 0.0);
  EXPECT_EQ(fp32.describe(), "precision fp32 (forced by the config)");
  config.precision = "bf16";
  if (nn::bf16_supported()) {
    EXPECT_EQ(choose_precision(config).precision, nn::Precision::kBf16);
  } else {
    EXPECT_THROW(choose_precision(config), AgentConfigError);
  }
}

TEST(PrecisionChoice, AutoMeasuresOncePerProcessAndTheAgentRunsItsChoice) {
  nn::set_threads(1);
  AgentConfig config = preset("tiny");
  ASSERT_EQ(config.precision, "auto");
  const PrecisionChoice first = choose_precision(config);
  const PrecisionChoice second = choose_precision(config);
  EXPECT_EQ(first.precision, second.precision);
  if (!bf16_measurable()) {
    EXPECT_EQ(first.precision, nn::Precision::kFp32);
    EXPECT_EQ(first.source, "no native bf16");
    return;
  }
  EXPECT_EQ(first.precision, nn::choose_precision(first.rates)) << first.describe();
  EXPECT_EQ(second.source, "measured earlier in this process");
  EXPECT_EQ(second.rates.bf16_gflops, first.rates.bf16_gflops);
  EXPECT_NE(first.describe().find("GFLOP/s in bf16 against"), std::string::npos)
      << first.describe();
  std::printf("[figures] tiny, 1 thread: %s\n", first.describe().c_str());
  config.replay.batch = 2, config.replay.length = 4;  // other shapes: measured anew
  const Agent agent(config);
  EXPECT_EQ(agent.precision_choice().source.rfind("measured in ", 0), 0u)
      << agent.precision_choice().source;
  EXPECT_EQ(nn::precision(), agent.precision_choice().precision);
}

TEST(PrecisionChoice, ARunKeepsItsFirstMeasurementOnTheSameCpu) {
  nn::set_threads(1);
  testing::TempDir dir;
  const AgentConfig config = preset("tiny");
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
                         std::regex("fp32_gflops=[^\n]+"), "fp32_gflops=123");
  std::ofstream(file) << edited;
  const PrecisionChoice again = choose_precision(config, dir.path());
  EXPECT_EQ(again.precision, nn::Precision::kFp32);
  EXPECT_NE(again.source.find("as measured at this run's start"), std::string::npos)
      << again.source;
  EXPECT_EQ(again.rates.fp32_gflops, 123.0);
  // Measured for another CPU (a run moved to another machine): measured again, file rewritten.
  std::ofstream(file) << std::regex_replace(edited, std::regex("measured_for=[^\n]+"),
                                            "measured_for=another CPU | threads 1 | shapes 1x1x1");
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
