// Benchmark: seconds per world-model update (the same work as the reference PyTorch script in
// shared/bench) and per full agent update (world model + intrinsic module + imagination +
// actor-critic) for a preset, and where the agent update's time goes by stage.
// Usage: common_agent_bench [--preset tiny|cpu|small] [--threads N] [--iters N] [--method disag]
//                           [--precision auto|fp32|bf16] [--kernels onednn|eigen]
//                           [--one-hot gather|dense]
//                           [--torch PATH/torch_agent_step.py]
//                           [--set agent.KEY=VALUE ...]  (e.g. --set replay.length=16)
// Prints, per stage and in total, seconds, the matrix-product FLOPs (nn::gemm_flops) and
// GFLOP/s, against the fp32 and bf16 product peaks measured in the same run. With --torch, and
// where python3 imports torch, also runs that PyTorch reference on the same preset and thread
// count and prints the ratio of the two, after PyTorch's own product rate (it needs an
// optimised BLAS such as libopenblas0-pthread: the bench warns when it runs on a slow one).
#include <sys/resource.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <random>
#include <string>
#include <tuple>
#include <vector>

#include "indrive/agent/agent.h"
#include "indrive/nn/kernels.h"

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

// The best GFLOP/s of the kernel layer's product on square sizes, at the current precision.
double product_peak() {
  double best = 0;
  for (const std::int64_t n : {512, 1024, 2048}) {
    std::vector<float> a(n * n, 0.5f), b(n * n, 0.25f), c(n * n);
    const nn::detail::GemmOperand ga{a.data(), n, n, false}, gb{b.data(), n, n, false};
    nn::detail::gemm(c.data(), ga, gb, false);  // creates the primitive
    const int reps = n >= 2048 ? 3 : 10;
    for (int r = 0; r < reps; ++r) {
      const auto t0 = std::chrono::steady_clock::now();
      nn::detail::gemm(c.data(), ga, gb, false);
      const double t = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      best = std::max(best, 2.0 * n * n * n / t / 1e9);
    }
  }
  return best;
}

// PyTorch's fp32 product rate at `threads` threads (GFLOP/s of a 1024 x 1024 x 1024 matmul), or a
// negative value when it cannot be measured. Debian's python3-torch multiplies through the
// system BLAS: with only the reference BLAS installed that is 5-6 GFLOP/s on this project's
// development machine, 140 with libopenblas0-pthread, and the reference's figures follow.
double torch_gemm_gflops(const std::string& python, int threads) {
  const std::string cmd =
      python + " -c 'import time, torch; torch.set_num_threads(" + std::to_string(threads) +
      "); a = torch.randn(1024, 1024); b = torch.randn(1024, 1024); [a @ b for _ in range(3)]; "
      "t = time.perf_counter(); [a @ b for _ in range(10)]; "
      "print(2 * 1024 ** 3 * 10 / (time.perf_counter() - t) / 1e9)' 2>/dev/null";
  FILE* pipe = popen(cmd.c_str(), "r");
  if (!pipe) return -1;
  char buf[256] = {0};
  const bool got = std::fgets(buf, sizeof buf, pipe) != nullptr;
  return pclose(pipe) == 0 && got ? std::atof(buf) : -1;
}

// Runs the PyTorch reference; its seconds per update, or a negative value (and why, on stderr).
// Prints PyTorch's product rate beside this engine's fp32 peak first, and a warning where it is
// under a tenth of it (a reference BLAS makes every ratio below meaningless).
double torch_reference(const std::string& script, const std::string& preset, int threads, int iters,
                       double our_fp32_peak) {
  // Debian's python3-torch is installed for the system interpreter, which another python3
  // earlier on PATH may hide.
  std::string python;
  for (const char* candidate : {"python3", "/usr/bin/python3"}) {
    if (std::system((std::string(candidate) + " -c 'import torch' >/dev/null 2>&1").c_str()) == 0) {
      python = candidate;
      break;
    }
  }
  if (python.empty()) {
    std::fprintf(stderr,
                 "torch reference skipped: python3 cannot import torch "
                 "(apt-get install python3-torch)\n");
    return -1;
  }
  const double gemm = torch_gemm_gflops(python, threads);
  std::printf("torch_gemm fp32_gflops=%.0f (this engine's fp32 peak %.0f)\n", gemm, our_fp32_peak);
  if (gemm >= 0 && gemm < 0.1 * our_fp32_peak) {
    std::printf(
        "torch_warning: PyTorch multiplies at %.0f GFLOP/s, under a tenth of this engine's "
        "fp32 peak: its BLAS is probably the reference one (apt-get install "
        "libopenblas0-pthread), so the ratio below compares against a slowed PyTorch\n",
        gemm);
  }
  const std::string cmd = python + " '" + script + "' --preset " + preset + " --threads " +
                          std::to_string(threads) + " --iters " + std::to_string(iters) + " 2>&1";
  FILE* pipe = popen(cmd.c_str(), "r");
  if (!pipe) return -1;
  std::string out;
  char buf[4096];
  while (std::fgets(buf, sizeof buf, pipe)) out += buf;
  const int rc = pclose(pipe);
  const std::size_t at = out.find("sec_per_update=");
  if (rc != 0 || at == std::string::npos) {
    std::fprintf(stderr, "torch reference failed (exit %d):\n%s", rc, out.c_str());
    return -1;
  }
  std::printf("torch_reference %s", out.c_str());
  return std::atof(out.c_str() + at + 15);
}

}  // namespace

int main(int argc, char** argv) {
  std::setvbuf(stdout, nullptr, _IOLBF, 0);  // figures survive a run cut short
  std::string preset = "tiny", method = "disag", precision = "auto", kernels = "onednn", torch;
  std::string one_hot = "gather";
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
    else if (key == "--precision")
      precision = argv[i + 1];
    else if (key == "--kernels")
      kernels = argv[i + 1];
    else if (key == "--one-hot")
      one_hot = argv[i + 1];
    else if (key == "--torch")
      torch = argv[i + 1];
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
    if (kernels != "onednn" && kernels != "eigen")
      throw std::runtime_error("--kernels wants onednn or eigen, got " + kernels);
    nn::set_use_onednn(kernels == "onednn");
    if (one_hot != "gather" && one_hot != "dense")
      throw std::runtime_error("--one-hot wants gather or dense, got " + one_hot);
    nn::set_gather_one_hot(one_hot == "gather");
    // The product peaks of this run: fp32, and bf16 where the CPU has it.
    nn::set_precision(nn::Precision::kFp32);
    const double peak_fp32 = product_peak();
    double peak_bf16 = 0;
    if (nn::bf16_supported() && nn::use_onednn()) {
      nn::set_precision(nn::Precision::kBf16);
      peak_bf16 = product_peak();
    }
    AgentConfig config = indrive::agent::preset(preset);
    indrive::agent::set_config_value(config, "intrinsic.method", method);
    indrive::agent::set_config_value(config, "precision", precision);
    for (const std::string& kv : sets) {
      const std::size_t eq = kv.find('=');
      if (eq == std::string::npos) throw std::runtime_error("--set wants KEY=VALUE, got " + kv);
      std::string key = kv.substr(0, eq);
      if (key.rfind("agent.", 0) == 0) key = key.substr(6);
      indrive::agent::set_config_value(config, key, kv.substr(eq + 1));
    }
    indrive::agent::Agent agent(config);
    if (!nn::use_onednn() && nn::precision() == nn::Precision::kBf16)
      throw std::runtime_error("--kernels eigen runs fp32 only: add --precision fp32");
    std::printf("%s%s\n", nn::kernel_report().c_str(),
                nn::gather_one_hot() ? "" : " (off: dense products, --one-hot dense)");
    std::printf("product_peak fp32_gflops=%.0f bf16_gflops=%.0f\n", peak_fp32, peak_bf16);
    const indrive::agent::PrecisionChoice& choice = agent.precision_choice();
    std::printf("precision_choice chosen=%s fp32_update_s=%.4f bf16_update_s=%.4f (%s)\n",
                std::string(nn::to_string(choice.precision)).c_str(), choice.fp32_update_s,
                choice.bf16_update_s, choice.describe().c_str());
    const SequenceBatch batch = random_batch(config, 1);
    const double frames = static_cast<double>(batch.batch) * batch.length;

    // World-model update only (forward, backward, Adam), as the reference script measures.
    nn::Adam adam(agent.world_model().params(), {.lr = 1e-4f, .eps = 1e-8f, .clip = 1000.0f});
    nn::Rng rng(1);
    Samples wm_samples, agent_samples;
    std::vector<indrive::agent::StepTiming> stages, stage_flops;
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
      if (i > 0)
        agent_samples.add(t0, u0), stages.push_back(agent.last_timing()),
            stage_flops.push_back(agent.last_flops());
    }
    std::int64_t params = 0;
    for (auto* g : agent.groups()) params += g->numel();
    const double wm = median(wm_samples.wall), full = median(agent_samples.wall);
    std::printf("preset=%s method=%s threads=%d B=%d T=%d H=%d wm_params=%lld all_params=%lld\n",
                preset.c_str(), method.c_str(), threads, batch.batch, batch.length,
                config.behavior.horizon,
                static_cast<long long>(agent.world_model().params().numel()),
                static_cast<long long>(params));
    // What every snapshot puts on the wire (the acting parameters only).
    std::printf("snapshot_mb=%.2f\n", static_cast<double>(agent.snapshot().size()) / 1e6);
    std::printf("wm_update sec=%.3f cpu_sec=%.3f page_faults=%.0f frames_per_sec=%.0f\n", wm,
                median(wm_samples.cpu), median(wm_samples.faults), frames / wm);
    std::printf(
        "agent_update sec=%.3f cpu_sec=%.3f page_faults=%.0f frames_per_sec=%.0f "
        "imagined_states_per_sec=%.0f\n",
        full, median(agent_samples.cpu), median(agent_samples.faults), frames / full,
        frames * config.behavior.horizon / full);
    // Median of each stage over the measured updates, its share of their sum, its product
    // FLOPs and GFLOP/s.
    const auto stage_median = [](const std::vector<indrive::agent::StepTiming>& runs,
                                 const std::string& name) {
      std::vector<double> v;
      for (const auto& s : runs) {
        for (const auto& [n, x] : s.as_metrics())
          if (n == name) v.push_back(x);
      }
      return median(v);
    };
    double stage_sum = 0, flops_sum = 0;
    std::vector<std::tuple<std::string, double, double>> medians;
    for (const auto& [name, unused] : indrive::agent::StepTiming{}.as_metrics()) {
      if (name == "time/update_s") continue;
      medians.emplace_back(name.substr(5, name.size() - 7), stage_median(stages, name),
                           stage_median(stage_flops, name));
      stage_sum += std::get<1>(medians.back());
      flops_sum += std::get<2>(medians.back());
    }
    std::printf("agent_update_stages");
    for (const auto& [name, sec, unused] : medians)
      std::printf(" %s=%.3f(%.0f%%)", name.c_str(), sec, stage_sum > 0 ? 100 * sec / stage_sum : 0);
    std::printf("\n");
    std::printf("agent_update_gflop");
    for (const auto& [name, sec, flops] : medians)
      std::printf(" %s=%.2f@%.0f/s", name.c_str(), flops / 1e9, sec > 0 ? flops / sec / 1e9 : 0);
    std::printf("\n");
    const double rate = flops_sum / full / 1e9;
    std::printf(
        "agent_update_total gflop=%.1f gflops=%.0f of_fp32_peak=%.0f%% of_bf16_peak=%.0f%%\n",
        flops_sum / 1e9, rate, 100 * rate / peak_fp32, peak_bf16 > 0 ? 100 * rate / peak_bf16 : 0);
    if (!torch.empty()) {
      const double ref =
          torch_reference(torch, preset, threads, std::max(2, std::min(iters, 3)), peak_fp32);
      if (ref > 0)
        std::printf("torch_ratio torch_sec=%.3f ours_sec=%.3f speedup=%.1fx\n", ref, full,
                    ref / full);
    }
    std::printf("arena_mb=%.0f arena_system_allocations=%zu\n",
                nn::current_graph().arena_capacity_bytes() / 1e6,
                nn::current_graph().arena_system_allocations());
  } catch (const std::exception& e) {
    std::fprintf(stderr, "common_agent_bench: %s\n", e.what());
    return 1;
  }
  return 0;
}
