// What the run's page costs on a long run: a run of 10,000 metrics lines (each line the last
// line of a real 100,000-step pretraining, its steps advanced), written as `indrive launch`
// writes it every 30 s. Prints the page's size, the mean and largest write time of 5 writes,
// and that time as a share of the 30 s refresh interval (the CPU the launcher takes from the
// learner and actors it shares the machine with).
//
//   build/bin/deploy_dashboard_bench [LINES]
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>

#include "indrive/deploy/dashboard.h"

namespace fs = std::filesystem;

int main(int argc, char** argv) {
  const int lines = argc > 1 ? std::stoi(argv[1]) : 10000;
  const fs::path source =
      fs::path(INDRIVE_SOURCE_DIR) / "docs/results/method/runs/s0-pretrain-disag/metrics.jsonl";
  std::ifstream in(source);
  std::string last;
  for (std::string line; std::getline(in, line);) {
    if (!line.empty()) last = line;
  }
  if (last.empty()) {
    std::fprintf(stderr, "no metrics line in %s\n", source.c_str());
    return 1;
  }
  const nlohmann::json templ = nlohmann::json::parse(last);

  const fs::path run =
      fs::temp_directory_path() / ("indrive-dashboard-bench-" + std::to_string(::getpid()));
  fs::create_directories(run);
  {
    std::ofstream out(run / "metrics.jsonl");
    for (int i = 0; i < lines; ++i) {
      nlohmann::json line = templ;
      line["env_steps"] = 100 * (i + 1);
      // Values that change from line to line, as a real run's do (a constant would compress
      // into fewer distinct numbers than a run writes).
      for (auto& [key, value] : line.items()) {
        if (value.is_number_float()) value = value.get<double>() * (1.0 + 1e-3 * (i % 97));
      }
      out << line.dump() << '\n';
    }
  }
  std::ofstream(run / "config.yaml") << "preset: tiny\n";

  indrive::deploy::DashboardInput input;
  input.runs = {indrive::deploy::single_run_group(run)};
  input.live_refresh_s = 30.0;
  // Cold: every file read whole (indrive dashboard RUN). Warm: the launcher's refresh, which
  // keeps a DashboardCache and parses only the lines appended since its last write (here 100,
  // what a learner logging every 1-3 s appends in 30 s at most).
  constexpr int kWrites = 5;
  indrive::deploy::DashboardCache cache;
  double cold = 0.0, warm = 0.0, warm_max = 0.0;
  indrive::deploy::DashboardStats stats;
  for (int k = 0; k < kWrites; ++k)
    cold += indrive::deploy::write_dashboard(input, run / "index.html").seconds;
  indrive::deploy::write_dashboard(input, run / "index.html", &cache);
  for (int k = 0; k < kWrites; ++k) {
    {
      std::ofstream out(run / "metrics.jsonl", std::ios::app);
      for (int i = 0; i < 100; ++i) {
        nlohmann::json line = templ;
        line["env_steps"] = 100 * (lines + 100 * k + i + 1);
        out << line.dump() << '\n';
      }
    }
    stats = indrive::deploy::write_dashboard(input, run / "index.html", &cache);
    warm += stats.seconds;
    warm_max = std::max(warm_max, stats.seconds);
  }
  cold /= kWrites;
  warm /= kWrites;
  std::printf("dashboard of %d metrics lines (%zu keys a line): %zu charts, %zu points\n", lines,
              templ.size(), stats.charts, stats.points);
  std::printf("  page %.2f MB\n", stats.bytes / 1e6);
  std::printf("  write, every file read whole (indrive dashboard RUN): mean %.3f s over %d\n", cold,
              kWrites);
  std::printf(
      "  write, appended lines only (indrive launch, --watch): mean %.3f s, max %.3f s over %d\n",
      warm, warm_max, kWrites);
  std::printf("  refreshed every 30 s: %.2f%% of one core\n", 100.0 * warm / 30.0);
  fs::remove_all(run);
  return 0;
}
