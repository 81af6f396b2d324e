// On a CPU without native bf16 everything runs, in fp32, and says so. The CPU is made to look
// like one by capping oneDNN's ISA at AVX512_CORE (no AVX512_BF16, no AMX) before oneDNN is
// first used: the variable is read once, at the first query.
#include <gtest/gtest.h>

#include <cstdlib>
#include <string>

#include "indrive/agent/agent.h"
#include "indrive/nn/kernels.h"

namespace {
const bool kCapped = (setenv("ONEDNN_MAX_CPU_ISA", "AVX512_CORE", 1), true);
}  // namespace

namespace indrive::agent {
namespace {

SequenceBatch tiny_batch(const AgentConfig& c) {
  SequenceBatch b;
  b.batch = 2, b.length = 4, b.height = b.width = c.world_model.image;
  const std::size_t n = static_cast<std::size_t>(b.batch) * b.length;
  b.frames.assign(n * b.height * b.width, 1);
  b.actions.assign(n, 3);
  b.is_first.assign(n, 0.0f), b.is_last.assign(n, 0.0f), b.is_terminal.assign(n, 0.0f);
  b.is_first[0] = b.is_first[b.length] = 1.0f;
  return b;
}

TEST(PrecisionFallback, WithoutNativeBf16AutoIsFp32AndBf16IsRefusedWithAReason) {
  ASSERT_TRUE(kCapped);
  nn::set_threads(1);
  EXPECT_FALSE(nn::bf16_supported());
  EXPECT_EQ(nn::resolve_precision("auto"), nn::Precision::kFp32);
  const std::string report = nn::kernel_report();
  std::printf("%s\n", report.c_str());
  if (nn::onednn_available()) {
    EXPECT_NE(report.find("no native bf16"), std::string::npos) << report;
    EXPECT_EQ(report.find("amx"), std::string::npos) << report;
  }

  AgentConfig config = preset("tiny");
  config.replay.batch = 2, config.replay.length = 4;
  Agent agent(config);  // precision auto
  EXPECT_EQ(nn::precision(), nn::Precision::kFp32);
  const TrainMetrics m = agent.train_step(tiny_batch(config));
  EXPECT_FALSE(m.empty());

  config.precision = "bf16";
  try {
    Agent refused(config);
    FAIL() << "bf16 accepted without native bf16";
  } catch (const AgentConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("agent.precision"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("fp32 or auto"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace indrive::agent
