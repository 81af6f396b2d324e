// Benchmark: seconds per world-model update (the same work as the reference PyTorch script in
// shared/bench) and per full agent update (world model + intrinsic module + imagination +
// actor-critic) for a preset.
// Usage: common_agent_bench [--preset tiny|cpu|small] [--threads N] [--iters N] [--method disag]
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
  }
  try {
    nn::set_threads(threads);
    AgentConfig config = indrive::agent::preset(preset);
    indrive::agent::set_config_value(config, "intrinsic.method", method);
    indrive::agent::Agent agent(config);
    const SequenceBatch batch = random_batch(config, 1);
    const double frames = static_cast<double>(batch.batch) * batch.length;

    // World-model update only (forward, backward, Adam), as the reference script measures.
    nn::Adam adam(agent.world_model().params(), {.lr = 1e-4f, .eps = 1e-8f, .clip = 1000.0f});
    nn::Rng rng(1);
    Samples wm_samples, agent_samples;
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
      if (i > 0) agent_samples.add(t0, u0);
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
    std::printf("arena_mb=%.0f arena_system_allocations=%zu\n",
                nn::current_graph().arena_capacity_bytes() / 1e6,
                nn::current_graph().arena_system_allocations());
  } catch (const std::exception& e) {
    std::fprintf(stderr, "common_agent_bench: %s\n", e.what());
    return 1;
  }
  return 0;
}
