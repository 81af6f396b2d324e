#include "indrive/agent/precision_choice.h"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <map>
#include <mutex>
#include <sstream>

#include "indrive/agent/agent.h"
#include "indrive/basics/stopwatch.h"
#include "indrive/nn/tensor.h"

namespace indrive::agent {
namespace fs = std::filesystem;

namespace {

using Clock = std::chrono::steady_clock;

std::string cpu_model() {
  std::ifstream in("/proc/cpuinfo");
  for (std::string line; std::getline(in, line);) {
    if (line.rfind("model name", 0) == 0) {
      const auto colon = line.find(':');
      if (colon == std::string::npos) return line;
      const auto start = line.find_first_not_of(' ', colon + 1);
      return start == std::string::npos ? "" : line.substr(start);
    }
  }
  return "unknown CPU";
}

// What a measurement holds for: the CPU, the thread count and the model's sizes and phase.
std::string measurement_key(const AgentConfig& c) {
  const WorldModelConfig& w = c.world_model;
  std::ostringstream key;
  key << cpu_model() << " | threads " << nn::threads() << " | image " << w.image << "x"
      << w.channels << " cnn " << w.cnn_depth << " deter " << w.deter << " units " << w.units
      << " latent " << w.stoch << "x" << w.classes << " batch " << c.replay.batch << "x"
      << c.replay.length << " horizon " << c.behavior.horizon << " " << method_label(c)
      << " ensemble " << c.intrinsic.ensemble << " " << to_string(c.phase);
  return key.str();
}

// A replay batch of the config's shape: random class ids and actions, one episode per row.
SequenceBatch synthetic_batch(const AgentConfig& c) {
  SequenceBatch b;
  b.batch = c.replay.batch, b.length = c.replay.length;
  b.height = b.width = c.world_model.image;
  const std::size_t n = static_cast<std::size_t>(b.batch) * b.length;
  b.frames.resize(n * b.height * b.width);
  std::uint32_t state = 12345;
  for (auto& f : b.frames)
    f = static_cast<std::uint8_t>((state = state * 1664525u + 1013904223u) >> 29);
  b.actions.resize(n);
  for (auto& a : b.actions)
    a = static_cast<int>(((state = state * 1664525u + 1013904223u) >> 16) % 9);
  b.is_first.assign(n, 0.0f), b.is_last.assign(n, 0.0f), b.is_terminal.assign(n, 0.0f);
  for (int i = 0; i < b.batch; ++i) b.is_first[static_cast<std::size_t>(i) * b.length] = 1.0f;
  if (c.phase != Phase::kPretrain) b.rewards.assign(n, 0.0f);
  return b;
}

// The faster of two timed updates of `agent` in `precision`, after one warm-up update (oneDNN
// primitives made, bf16 copies kept).
double update_seconds(Agent& agent, const SequenceBatch& batch, nn::Precision precision) {
  nn::set_precision(precision);
  agent.train_step(batch);
  double best = 0.0;
  for (int i = 0; i < 2; ++i) {
    const auto start = Clock::now();
    agent.train_step(batch);
    const double s = seconds_since(start);
    best = i == 0 ? s : std::min(best, s);
  }
  return best;
}

// The choices measured in this process, by measurement_key.
std::mutex g_mutex;
std::map<std::string, PrecisionChoice> g_measured;

PrecisionChoice forced(const std::string& text) {
  try {
    return {.precision = nn::resolve_precision(text), .source = "forced"};
  } catch (const nn::PrecisionError& e) {
    throw AgentConfigError(std::string("agent.") + e.what());
  }
}

std::map<std::string, std::string> read_fields(const fs::path& file) {
  std::map<std::string, std::string> fields;
  std::ifstream in(file);
  for (std::string line; std::getline(in, line);) {
    if (line.empty() || line[0] == '#') continue;
    const auto equals = line.find('=');
    if (equals != std::string::npos) fields[line.substr(0, equals)] = line.substr(equals + 1);
  }
  return fields;
}

}  // namespace

nn::Precision choose_by_update_time(double fp32_update_s, double bf16_update_s, double margin) {
  return fp32_update_s > 0.0 && bf16_update_s > 0.0 && fp32_update_s >= margin * bf16_update_s
             ? nn::Precision::kBf16
             : nn::Precision::kFp32;
}

std::string PrecisionChoice::describe() const {
  char text[320];
  if (source == "forced") {
    std::snprintf(text, sizeof text, "precision %s (forced by the config)",
                  std::string(nn::to_string(precision)).c_str());
  } else if (bf16_update_s <= 0.0) {
    std::snprintf(text, sizeof text, "precision auto: fp32 (no native bf16 products here)");
  } else {
    std::snprintf(text, sizeof text,
                  "precision auto: %s (an update took %.4g s in bf16 against %.4g s in fp32; "
                  "bf16 needs %.2fx; %s)",
                  std::string(nn::to_string(precision)).c_str(), bf16_update_s, fp32_update_s,
                  kBf16Margin, source.c_str());
  }
  return text;
}

std::optional<PrecisionChoice> known_precision(const AgentConfig& config) {
  if (config.precision != "auto") return forced(config.precision);
  if (!nn::bf16_supported() || !nn::use_onednn()) {
    return PrecisionChoice{.precision = nn::Precision::kFp32, .source = "no native bf16"};
  }
  std::lock_guard<std::mutex> lock(g_mutex);
  const auto it = g_measured.find(measurement_key(config));
  if (it == g_measured.end()) return std::nullopt;
  PrecisionChoice again = it->second;
  again.source = "measured earlier in this process";
  return again;
}

PrecisionChoice measure_precision(Agent& agent) {
  const AgentConfig& config = agent.config();
  const auto start = Clock::now();
  const std::vector<std::uint8_t> before = agent.checkpoint_bytes();
  const SequenceBatch batch = synthetic_batch(config);
  PrecisionChoice choice;
  choice.fp32_update_s = update_seconds(agent, batch, nn::Precision::kFp32);
  choice.bf16_update_s = update_seconds(agent, batch, nn::Precision::kBf16);
  agent.load_checkpoint(before, "the agent before its precision measurement");
  // The arena and the kept bf16 copies start afresh, as in an agent that never measured: kept,
  // the measurement's layout made the next updates 16% slower on `cpu`.
  nn::current_graph().release_memory();
  nn::detail::forget_graph_conversions(/*reset=*/true);
  choice.precision = choose_by_update_time(choice.fp32_update_s, choice.bf16_update_s);
  choice.seconds = seconds_since(start);
  char source[64];
  std::snprintf(source, sizeof source, "measured in %.1f s", choice.seconds);
  choice.source = source;
  std::lock_guard<std::mutex> lock(g_mutex);
  g_measured[measurement_key(config)] = choice;
  return choice;
}

std::optional<PrecisionChoice> run_precision(const AgentConfig& config, const fs::path& run_dir) {
  const fs::path file = run_dir / "precision.txt";
  if (config.precision == "auto" && fs::exists(file)) {
    auto fields = read_fields(file);
    if (fields["measured_for"] == measurement_key(config) &&
        (fields["chosen"] == "fp32" || (fields["chosen"] == "bf16" && nn::bf16_supported()))) {
      PrecisionChoice choice{.precision = nn::resolve_precision(fields["chosen"]),
                             .source = "as measured at this run's start, " + file.string()};
      try {
        choice.fp32_update_s = std::stod(fields["fp32_update_s"]);
        choice.bf16_update_s = std::stod(fields["bf16_update_s"]);
      } catch (const std::exception&) {
        // the choice stands; the times are only for the log
      }
      return choice;
    }
  }
  return known_precision(config);
}

void record_run_precision(const AgentConfig& config, const PrecisionChoice& choice,
                          const fs::path& run_dir) {
  if (choice.bf16_update_s <= 0.0 || choice.source.rfind("as measured at this run", 0) == 0) {
    return;  // nothing measured, or read from this file
  }
  fs::create_directories(run_dir);
  std::ofstream out(run_dir / "precision.txt");
  out << "# precision auto: the agent's update timed in both precisions at this run's start;\n"
      << "# a restarted learner on the same CPU keeps this choice (delete the file to measure "
         "again)\n"
      << "measured_for=" << measurement_key(config) << "\n"
      << "fp32_update_s=" << choice.fp32_update_s << "\n"
      << "bf16_update_s=" << choice.bf16_update_s << "\n"
      << "bf16_margin=" << kBf16Margin << "\n"
      << "chosen=" << nn::to_string(choice.precision) << "\n";
}

}  // namespace indrive::agent
