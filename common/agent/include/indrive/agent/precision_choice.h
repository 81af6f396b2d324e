// Which precision the agent's matrix products run in. "fp32" and "bf16" are forced; "auto"
// times the model's own product shapes in both precisions (about 0.1 s) and takes bf16 only
// where it is at least nn::kBf16Margin times as fast: a CPU with AVX512_BF16 may multiply bf16 at
// half its fp32 rate, and only a measurement tells.
//
//   const PrecisionChoice choice = choose_precision(config, run_dir);  // measured once per run
//   config.precision = std::string(nn::to_string(choice.precision));
//   INDRIVE_LOG(kInfo, "learner") << choice.describe();
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include "indrive/agent/agent_config.h"
#include "indrive/nn/kernels.h"

namespace indrive::agent {

// The model's main products, each as its forward product and both backward ones: the encoder's
// first two convolutions (as im2col products), the sequence model's GRU and MLPs over the
// replay batch, and the actor-critic's MLPs over the imagined states.
std::vector<nn::ProductShape> product_shapes(const AgentConfig& config);

struct PrecisionChoice {
  nn::Precision precision = nn::Precision::kFp32;
  nn::PrecisionRates rates;  // zero where nothing was measured (forced, or no native bf16)
  // "forced" (fp32 or bf16 in the config), "measured", "measured earlier in this process", or
  // the file of the run that holds the measurement.
  std::string source;
  // One line for the log, e.g. "precision auto: bf16 (the model's products at 621 GFLOP/s in
  // bf16 against 362 in fp32; bf16 needs 1.10x; measured in 0.12 s)".
  std::string describe() const;
};

// config.precision resolved. "bf16" on a CPU without native bf16 throws AgentConfigError, as
// nn::resolve_precision does. "auto" is measured once per process for each set of shapes and
// thread count, so agents of one process agree.
PrecisionChoice choose_precision(const AgentConfig& config);

// As above, but "auto" is measured once per run: the first call writes
// <run_dir>/precision.txt, and later calls (a restarted or resumed learner) take its choice when
// it was measured on this CPU model with this thread count and these shapes; otherwise they
// measure again and rewrite it.
PrecisionChoice choose_precision(const AgentConfig& config, const std::filesystem::path& run_dir);

}  // namespace indrive::agent
