// Benchmark: seconds per world-model update (the same work as the reference PyTorch script in
// shared/bench) and per full agent update (world model + intrinsic module + imagination +
// actor-critic) for a preset, and where the agent update's time goes by stage.
// Usage: common_agent_bench [--preset tiny|cpu|small] [--threads N] [--iters N] [--method disag]
//                           [--set agent.KEY=VALUE ...]  (e.g. --set replay.length=16)
#include <sys/resource.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <random>
#include <string>
#include <vector>

#include "indrive/common/agent/agent.h"

namespace {

using indrive::agent::AgentConfig;
using indrive::agent::SequenceBatch;
namespace nn = indrive::nn;

SequenceBatch random_batch(const AgentConfig& c, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  SequenceBatch b;
  b.batch = c.replay.batch, b.length = c.replay.length;
  b.height = b.width = c.world_model.image;
  const std::size_t n = static_cast<std::size_t>(b.batch) * b.length;
  b.frames.resize(n * b.height * b.width);
  for (auto& f : b.frames) f = static_cast<std::uint8_t>(rng() % 8);
  b.actions.resize(n);
  for (auto& a : b.actions) a = static_cast<int>(rng() % 9);
  b.is_first.assign(n, 0.0f), b.is_last.assign(n, 0.0f), b.is_terminal.assign(n, 0.0f);
  for (int i = 0; i < b.batch; ++i) b.is_first[i * b.length] = 1.0f;
  return b;
}

// Median; for an even count the mean of the middle two (with two samples, the larger one
// alone would report the slower update).
double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  const std::size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

// CPU seconds of the whole process (all threads) and its minor page faults so far: on a shared
// machine CPU time shows the work done where wall time also shows waiting for a core.
struct Usage {
  double cpu = 0, faults = 0;
  static Usage now() {
    timespec ts;
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
    rusage u;
    getrusage(RUSAGE_SELF, &u);
    return {static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec),
            static_cast<double>(u.ru_minflt)};
  }
};

// Wall seconds, CPU seconds and page faults of each measured update.
struct Samples {
  std::vector<double> wall, cpu, faults;
  void add(std::chrono::steady_clock::time_point t0, const Usage& u0) {
    const Usage u1 = Usage::now();
    wall.push_back(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
    cpu.push_back(u1.cpu - u0.cpu);
    faults.push_back(u1.faults - u0.faults);
  }
};

}  // namespace

int main(int argc, char** argv) {
  std::string preset = "tiny", method = "disag";
  std::vector<std::string> sets;
  int threads = 2, iters = 5;
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string key = argv[i];
    if (key == "--preset")
      preset = argv[i + 1];
    else if (key == "--threads")
      threads = std::atoi(argv[i + 1]);
    else if (key == "--iters")
      iters = std::atoi(argv[i + 1]);
    else if (key == "--method")
      method = argv[i + 1];
    else if (key == "--set")
      sets.push_back(argv[i + 1]);
    else {
      std::fprintf(stderr,
                   "common_agent_bench: unknown option %s (see the usage at the top of "
                   "agent_bench.cc)\n",
                   key.c_str());
      return 2;
    }
  }
  try {
    nn::set_threads(threads);
    AgentConfig config = indrive::agent::preset(preset);
    indrive::agent::set_config_value(config, "intrinsic.method", method);
    for (const std::string& kv : sets) {
      const std::size_t eq = kv.find('=');
      if (eq == std::string::npos) throw std::runtime_error("--set wants KEY=VALUE, got " + kv);
      std::string key = kv.substr(0, eq);
      if (key.rfind("agent.", 0) == 0) key = key.substr(6);
      indrive::agent::set_config_value(config, key, kv.substr(eq + 1));
    }
    indrive::agent::Agent agent(config);
    const SequenceBatch batch = random_batch(config, 1);
    const double frames = static_cast<double>(batch.batch) * batch.length;

    // World-model update only (forward, backward, Adam), as the reference script measures.
    nn::Adam adam(agent.world_model().params(), {.lr = 1e-4f, .eps = 1e-8f, .clip = 1000.0f});
    nn::Rng rng(1);
    Samples wm_samples, agent_samples;
    std::vector<indrive::agent::StepTiming> stages;
    for (int i = 0; i <= iters; ++i) {
      const auto t0 = std::chrono::steady_clock::now();
      const Usage u0 = Usage::now();
      nn::current_graph().reset();
      auto out = agent.world_model().observe(batch, false, rng);
      nn::current_graph().backward(out.loss);
      adam.step();
      if (i > 0) wm_samples.add(t0, u0);
    }
    for (int i = 0; i <= iters; ++i) {
      const auto t0 = std::chrono::steady_clock::now();
      const Usage u0 = Usage::now();
      agent.train_step(batch);
      if (i > 0) agent_samples.add(t0, u0), stages.push_back(agent.last_timing());
    }
    std::int64_t params = 0;
    for (auto* g : agent.groups()) params += g->numel();
    const double wm = median(wm_samples.wall), full = median(agent_samples.wall);
    std::printf("preset=%s method=%s threads=%d B=%d T=%d H=%d wm_params=%lld all_params=%lld\n",
                preset.c_str(), method.c_str(), threads, batch.batch, batch.length,
                config.behavior.horizon,
                static_cast<long long>(agent.world_model().params().numel()),
                static_cast<long long>(params));
    std::printf("wm_update sec=%.3f cpu_sec=%.3f page_faults=%.0f frames_per_sec=%.0f\n", wm,
                median(wm_samples.cpu), median(wm_samples.faults), frames / wm);
    std::printf(
        "agent_update sec=%.3f cpu_sec=%.3f page_faults=%.0f frames_per_sec=%.0f "
        "imagined_states_per_sec=%.0f\n",
        full, median(agent_samples.cpu), median(agent_samples.faults), frames / full,
        frames * config.behavior.horizon / full);
    // Median of each stage over the measured updates, and its share of their sum.
    std::printf("agent_update_stages");
    double stage_sum = 0;
    std::vector<std::pair<std::string, double>> medians;
    for (const auto& [name, unused] : indrive::agent::StepTiming{}.as_metrics()) {
      if (name == "time/update_s") continue;
      std::vector<double> v;
      for (const auto& s : stages) {
        for (const auto& [n, x] : s.as_metrics())
          if (n == name) v.push_back(x);
      }
      medians.emplace_back(name.substr(5, name.size() - 7), median(v));
      stage_sum += medians.back().second;
    }
    for (const auto& [name, sec] : medians)
      std::printf(" %s=%.3f(%.0f%%)", name.c_str(), sec, stage_sum > 0 ? 100 * sec / stage_sum : 0);
    std::printf("\n");
    std::printf("arena_mb=%.0f arena_system_allocations=%zu\n",
                nn::current_graph().arena_capacity_bytes() / 1e6,
                nn::current_graph().arena_system_allocations());
  } catch (const std::exception& e) {
    std::fprintf(stderr, "common_agent_bench: %s\n", e.what());
    return 1;
  }
  return 0;
}
