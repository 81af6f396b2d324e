// Which precision the agent's matrix products run in. "fp32" and "bf16" are forced; "auto"
// times the agent's own update in both precisions (a throwaway agent of the same config, on a
// synthetic batch, one warm-up and two timed updates each) and takes bf16 only where it is at
// least kBf16Margin times as fast. A CPU flag says whether bf16 products run, not whether they
// are faster: a 2-core Xeon with AVX512_BF16 multiplied bf16 at half its fp32 rate, and the
// products timed alone mispredicted the update on an AMD EPYC (they leave out that an update
// reuses each bf16 copy).
//
//   const PrecisionChoice choice = choose_precision(config, run_dir);  // measured once per run
//   config.precision = std::string(nn::to_string(choice.precision));
//   INDRIVE_LOG(kInfo, "learner") << choice.describe();
#pragma once

#include <filesystem>
#include <string>

#include "indrive/agent/agent_config.h"
#include "indrive/nn/kernels.h"

namespace indrive::agent {

// bf16 only where an update measured at least this much faster: the 5% that a wrong choice may
// cost, and more than two updates' timing noise on an idle machine.
constexpr double kBf16Margin = 1.05;

struct PrecisionChoice {
  nn::Precision precision = nn::Precision::kFp32;
  // The faster of two timed updates in each precision; 0 where nothing was timed (forced, or no
  // native bf16).
  double fp32_update_s = 0.0;
  double bf16_update_s = 0.0;
  double seconds = 0.0;  // the measurement's wall time, warm-ups and agents' set-up included
  // "forced" (fp32 or bf16 in the config), "no native bf16", "measured", "measured earlier in
  // this process", or the run's file that holds the measurement.
  std::string source;
  // One line for the log, e.g. "precision auto: bf16 (an update took 1.381 s in bf16 against
  // 1.543 s in fp32; bf16 needs 1.05x; measured in 9.4 s)".
  std::string describe() const;
};

// The rule: bf16 where fp32_update_s >= margin * bf16_update_s (both measured), else fp32.
nn::Precision choose_by_update_time(double fp32_update_s, double bf16_update_s,
                                    double margin = kBf16Margin);

// config.precision resolved. "bf16" on a CPU without native bf16 throws AgentConfigError, as
// nn::resolve_precision does. "auto" is measured once per process for each model and thread
// count, so agents of one process agree. It takes about 6 updates of the model: 0.3 s on
// `tiny`, 10 s on `cpu`, a minute on `small`.
PrecisionChoice choose_precision(const AgentConfig& config);

// As above, but "auto" is measured once per run: the first call writes
// <run_dir>/precision.txt, and later calls (a restarted or resumed learner) take its choice when
// it was measured on this CPU model with this thread count and this model; otherwise they
// measure again and rewrite it.
PrecisionChoice choose_precision(const AgentConfig& config, const std::filesystem::path& run_dir);

}  // namespace indrive::agent
