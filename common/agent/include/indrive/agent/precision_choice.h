// Which precision the agent's matrix products run in. "fp32" and "bf16" are forced; "auto"
// times the agent's own update in both precisions (on a synthetic batch, one warm-up and two
// timed updates each, the agent restored bitwise afterwards) and takes bf16 only where it is at
// least kBf16Margin times as fast. A CPU flag says whether bf16 products run, not whether they
// are faster: a 2-core Xeon with AVX512_BF16 multiplied bf16 at half its fp32 rate, and the
// products timed alone mispredicted the update on an AMD EPYC (they leave out that an update
// reuses each bf16 copy).
//
//   Agent agent(config);   // "auto": the agent times its own update, then restores itself
//   INDRIVE_LOG(kInfo, "learner") << agent.precision_choice().describe();
#pragma once

#include <filesystem>
#include <optional>
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

class Agent;

// config.precision resolved where no measurement is needed: forced, no native bf16, or "auto"
// already measured in this process for this model and thread count (so agents of one process
// agree). nullopt: "auto" still to be measured, by the agent itself (measure_precision).
// "bf16" on a CPU without native bf16 throws AgentConfigError, as nn::resolve_precision does.
std::optional<PrecisionChoice> known_precision(const AgentConfig& config);

// Times `agent`'s own update in both precisions (one warm-up and two timed updates each, on a
// synthetic batch of its config's shape), then restores the agent bitwise from the bytes it had
// (checkpoint_bytes), chooses by choose_by_update_time and records the choice for the process.
// About 6 updates: 0.3 s on `tiny`, 10 s on `cpu`, a minute on `small`. Timing the agent
// itself matters: a second agent made after throwaway ones ran its update 5-15% slower.
PrecisionChoice measure_precision(Agent& agent);

// For a run: the choice kept in <run_dir>/precision.txt when it was measured on this CPU model
// with this thread count and this model (a restarted or resumed learner), else
// known_precision(config).
std::optional<PrecisionChoice> run_precision(const AgentConfig& config,
                                             const std::filesystem::path& run_dir);
// Writes `choice` (a measured one) to <run_dir>/precision.txt for run_precision to find.
void record_run_precision(const AgentConfig& config, const PrecisionChoice& choice,
                          const std::filesystem::path& run_dir);

}  // namespace indrive::agent
