#include "indrive/agent/precision_choice.h"

#include <algorithm>
#include <cstdio>
#include <fstream>
#include <map>
#include <mutex>
#include <sstream>

#include "indrive/nn/tensor.h"

namespace indrive::agent {
namespace fs = std::filesystem;

namespace {

constexpr double kBudgetS = 0.1;

// The forward product (m, k) x (k, n) and its two backward products.
void add_layer(std::vector<nn::ProductShape>& shapes, std::int64_t m, std::int64_t k,
               std::int64_t n) {
  shapes.push_back({m, k, n});  // forward
  shapes.push_back({m, n, k});  // gradient of the input
  shapes.push_back({k, m, n});  // gradient of the weights
}

std::string cpu_model() {
  std::ifstream in("/proc/cpuinfo");
  for (std::string line; std::getline(in, line);) {
    if (line.rfind("model name", 0) == 0) {
      const auto colon = line.find(':');
      return colon == std::string::npos ? line
                                        : line.substr(line.find_first_not_of(' ', colon + 1));
    }
  }
  return "unknown CPU";
}

// What a measurement holds for: the CPU, the thread count and the shapes.
std::string measurement_key(const std::vector<nn::ProductShape>& shapes) {
  std::ostringstream key;
  key << cpu_model() << " | threads " << nn::threads() << " | shapes";
  for (const auto& s : shapes) key << ' ' << s.m << 'x' << s.k << 'x' << s.n;
  return key.str();
}

PrecisionChoice measured(const nn::PrecisionRates& rates, std::string source) {
  return {.precision = nn::choose_precision(rates), .rates = rates, .source = std::move(source)};
}

PrecisionChoice forced(const std::string& text) {
  try {
    return {.precision = nn::resolve_precision(text), .source = "forced"};
  } catch (const nn::PrecisionError& e) {
    throw AgentConfigError(std::string("agent.") + e.what());
  }
}

// Once per process for each key: agents of one process run in one precision.
nn::PrecisionRates process_rates(const std::vector<nn::ProductShape>& shapes, bool* fresh) {
  static std::mutex mutex;
  static std::map<std::string, nn::PrecisionRates> rates;
  std::lock_guard<std::mutex> lock(mutex);
  const std::string key = measurement_key(shapes);
  const auto it = rates.find(key);
  *fresh = it == rates.end();
  if (!*fresh) return it->second;
  return rates[key] = nn::measure_product_rates(shapes, kBudgetS);
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

std::vector<nn::ProductShape> product_shapes(const AgentConfig& config) {
  const WorldModelConfig& w = config.world_model;
  const std::int64_t rows = static_cast<std::int64_t>(config.replay.batch) * config.replay.length;
  std::vector<nn::ProductShape> shapes;
  // Encoder: 4x4 convolutions of stride 2; rows are output pixels of every frame.
  const std::int64_t half = w.image / 2, quarter = w.image / 4;
  add_layer(shapes, rows * half * half, 16 * w.channels, w.cnn_depth);
  add_layer(shapes, rows * quarter * quarter, 16 * w.cnn_depth, 2 * w.cnn_depth);
  // Sequence model over the replay batch: the GRU's three gates and the MLPs into and out of it.
  add_layer(shapes, rows, w.stoch_dim() + w.units, w.units);
  add_layer(shapes, rows, w.units + w.deter, 3 * w.deter);
  add_layer(shapes, rows, w.feat_dim(), w.units);
  add_layer(shapes, rows, w.units, w.units);
  // The actor-critic over the imagined states (one start per replay step).
  add_layer(shapes, rows, w.feat_dim(), w.units);
  return shapes;
}

std::string PrecisionChoice::describe() const {
  char text[320];
  if (source == "forced") {
    std::snprintf(text, sizeof text, "precision %s (forced by the config)",
                  std::string(nn::to_string(precision)).c_str());
  } else if (rates.bf16_gflops <= 0.0) {
    std::snprintf(text, sizeof text, "precision auto: fp32 (no native bf16 products here)");
  } else {
    std::snprintf(text, sizeof text,
                  "precision auto: %s (the model's products at %.0f GFLOP/s in bf16 against %.0f "
                  "in fp32; bf16 needs %.2fx; %s)",
                  std::string(nn::to_string(precision)).c_str(), rates.bf16_gflops,
                  rates.fp32_gflops, nn::kBf16Margin, source.c_str());
  }
  return text;
}

PrecisionChoice choose_precision(const AgentConfig& config) {
  if (config.precision != "auto") return forced(config.precision);
  if (!nn::bf16_supported() || !nn::use_onednn()) {
    return {.precision = nn::Precision::kFp32, .source = "no native bf16"};
  }
  bool fresh = false;
  const nn::PrecisionRates rates = process_rates(product_shapes(config), &fresh);
  char source[64];
  std::snprintf(source, sizeof source, "measured in %.2f s", rates.seconds);
  return measured(rates, fresh ? source : "measured earlier in this process");
}

PrecisionChoice choose_precision(const AgentConfig& config, const fs::path& run_dir) {
  if (config.precision != "auto") return forced(config.precision);
  const fs::path file = run_dir / "precision.txt";
  const std::string key = measurement_key(product_shapes(config));
  if (fs::exists(file)) {
    auto fields = read_fields(file);
    if (fields["measured_for"] == key &&
        (fields["chosen"] == "fp32" || (fields["chosen"] == "bf16" && nn::bf16_supported()))) {
      PrecisionChoice choice{.precision = nn::resolve_precision(fields["chosen"]),
                             .source = "as measured at this run's start, " + file.string()};
      try {
        choice.rates.fp32_gflops = std::stod(fields["fp32_gflops"]);
        choice.rates.bf16_gflops = std::stod(fields["bf16_gflops"]);
      } catch (const std::exception&) {
        // the choice stands; the rates are only for the log
      }
      return choice;
    }
  }
  PrecisionChoice choice = choose_precision(config);
  fs::create_directories(run_dir);
  std::ofstream out(file);
  out << "# precision auto: the model's products timed in both precisions at this run's start;\n"
      << "# a restarted learner on the same CPU keeps this choice (delete the file to measure "
         "again)\n"
      << "measured_for=" << key << "\n"
      << "fp32_gflops=" << choice.rates.fp32_gflops << "\n"
      << "bf16_gflops=" << choice.rates.bf16_gflops << "\n"
      << "bf16_margin=" << nn::kBf16Margin << "\n"
      << "chosen=" << nn::to_string(choice.precision) << "\n";
  return choice;
}

}  // namespace indrive::agent
