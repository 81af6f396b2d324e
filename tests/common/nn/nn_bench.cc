// Benchmark of the nn engine:
//  (a) single-precision GEMM throughput of the engine's matmul at large sizes (the peak the
//      rest is compared with);
//  (b) one full world-model-shaped update at a preset of ARCHITECTURE.md: conv encoder over
//      B*T images, a T-step RSSM unroll (GRU, prior and posterior heads, straight-through
//      sampling with 1% unimix), conv decoder, KL with free bits, continuation head, backward,
//      global-norm clipping and Adam. The model mirrors shared/bench/torch_wm_step.py, so the two
//      timings measure the same work.
//
//  (c) the one-hot gather of linear_one_hot_tail on the shape of the disagreement ensemble's
//      first layer (512 imagined states, 8 members' weights side by side): microseconds per
//      call, gathered and as a dense product (nn::set_gather_one_hot(false)).
//
// Usage: nn_bench [--preset tiny|cpu|small] [--threads N] [--iters N] [--skip-gemm]
// Prints seconds per update, the FLOP count used (GEMM and convolution multiply-adds x2; the
// backward pass counted as twice the forward, except the input gradient of the first conv,
// which is not computed) and GFLOP/s.
#include <sys/resource.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <string>
#include <vector>

#include "indrive/basics/stopwatch.h"
#include "indrive/nn/kernels.h"
#include "indrive/nn/nn.h"

namespace {

using namespace indrive::nn;
using Clock = std::chrono::steady_clock;
using indrive::seconds_since;

// CPU seconds used by the whole process (all threads): on a shared machine this shows the
// work done, while wall time also shows waiting for a core.
double process_cpu_seconds() {
  timespec ts;
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

// Minor page faults of the process so far: a step that reuses its memory makes almost none.
double page_faults() {
  rusage u;
  getrusage(RUSAGE_SELF, &u);
  return static_cast<double>(u.ru_minflt);
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

// (a) GEMM peak: C = A * B for square sizes, best of several repetitions.
double gemm_peak() {
  double best = 0;
  Rng rng(1);
  for (int n : {512, 1024, 2048}) {
    Graph& g = current_graph();
    g.reset();
    NoGradGuard no_grad;
    Tensor a = empty({n, n}), b = empty({n, n});
    for (float& v : a.values()) v = rng.uniform() - 0.5f;
    for (float& v : b.values()) v = rng.uniform() - 0.5f;
    const int reps = n >= 2048 ? 3 : 8;
    std::vector<double> times;
    for (int r = 0; r < reps; ++r) {
      const auto t0 = Clock::now();
      Tensor c = matmul(a, b);
      times.push_back(seconds_since(t0));
      if (c.data()[0] == 12345.0f) std::printf(" ");  // keep the result alive
    }
    const double t = *std::min_element(times.begin(), times.end());
    const double gflops = 2.0 * n * n * n / t / 1e9;
    std::printf("gemm %5d x %5d x %5d: %8.2f ms  %7.1f GFLOP/s\n", n, n, n, t * 1e3, gflops);
    best = std::max(best, gflops);
  }
  current_graph().reset();
  return best;
}

struct Preset {
  const char* name;
  int image, depth, deter, units, stoch, classes, batch, seq;
};

constexpr Preset kPresets[] = {
    {"tiny", 32, 8, 128, 128, 16, 16, 8, 16},
    {"cpu", 64, 16, 256, 256, 32, 32, 16, 64},
    {"small", 128, 32, 512, 512, 32, 32, 16, 64},
};
constexpr int kActions = 9;

// (c): linear_one_hot_tail over [deter, one-hot stoch, one-hot action] rows into 8 * units
// columns, on the calling thread (as the ensemble's reward chunks run), median of 200 calls.
void one_hot_tail_bench(const Preset& p) {
  constexpr int kRows = 512, kMembers = 8;
  const int stoch = p.stoch * p.classes, in = p.deter + stoch + kActions;
  const int cols = kMembers * p.units;
  Rng rng(5);
  std::vector<float> x(static_cast<std::size_t>(kRows) * in, 0.0f);
  for (int r = 0; r < kRows; ++r) {
    float* row = x.data() + static_cast<std::size_t>(r) * in;
    for (int d = 0; d < p.deter; ++d) row[d] = rng.normal();
    for (int g = 0; g < p.stoch; ++g) row[p.deter + g * p.classes + rng.below(p.classes)] = 1;
    row[p.deter + stoch + rng.below(kActions)] = 1;
  }
  std::vector<float> w(static_cast<std::size_t>(in) * cols);
  for (float& v : w) v = 0.01f * rng.normal();
  const int saved_threads = threads();
  set_threads(1);
  for (const bool gather : {true, false}) {
    set_gather_one_hot(gather);
    std::vector<double> times;
    Graph& g = current_graph();
    for (int i = 0; i < 220; ++i) {
      g.reset();
      NoGradGuard no_grad;
      const Tensor xt = constant(Shape{kRows, in}, x), wt = constant(Shape{in, cols}, w);
      const auto t0 = Clock::now();
      const Tensor y = linear_one_hot_tail(xt, wt, Tensor(), p.deter);
      if (i >= 20) times.push_back(seconds_since(t0));
      if (y.data()[0] == 12345.0f) std::printf(" ");  // keep the result alive
    }
    std::printf("one_hot_tail rows=%d dense=%d one_hot=%d ones_per_row=%d cols=%d %s: %.1f us\n",
                kRows, p.deter, stoch + kActions, p.stoch + 1, cols,
                gather ? "gathered" : "product", median(times) * 1e6);
  }
  set_gather_one_hot(true);
  set_threads(saved_threads);
}

// The world model of torch_wm_step.py.
struct WorldModel {
  WorldModel(const Preset& p, ParamGroup& group, Rng& rng)
      : p(p),
        stoch(p.stoch * p.classes),
        enc(group, "enc", {.image = p.image, .channels = 3, .depth = p.depth}, rng),
        img_in(group, "img_in", stoch + kActions, {.units = p.units, .layers = 1}, rng),
        gru(group, "gru", p.units, p.deter, rng),
        img_out(group, "img_out", p.deter, {.units = p.units, .layers = 1, .out = stoch}, rng),
        obs_out(group, "obs_out", p.deter + enc.embed_dim(),
                {.units = p.units, .layers = 1, .out = stoch}, rng),
        dec(group, "dec", p.deter + stoch, {.image = p.image, .channels = 3, .depth = p.depth},
            rng),
        cont(group, "cont", p.deter + stoch, {.units = p.units, .layers = 2, .out = 1}, rng) {}

  // obs is (T*B, H, W, 3) time-major; act is (T*B, A); cont_target is (T*B, 1).
  Tensor loss(Tensor obs, Tensor act, Tensor cont_target, Rng& rng) {
    const int B = p.batch, T = p.seq;
    Tensor embed = enc(add_scalar(obs, -0.5f));  // (T*B, E)
    Tensor h = zeros({B, p.deter});
    Tensor z = zeros({B, stoch});
    std::vector<Tensor> posts, priors, feats;
    for (int t = 0; t < T; ++t) {
      Tensor a = slice(act, t * B, (t + 1) * B, 0);
      Tensor e = slice(embed, t * B, (t + 1) * B, 0);
      h = gru(img_in(concat({z, a})), h);
      Tensor prior = unimix_probs(img_out(h), p.classes);
      Tensor post = unimix_probs(obs_out(concat({h, e})), p.classes);
      z = sample_straight_through(post, p.classes, rng);
      posts.push_back(post);
      priors.push_back(prior);
      feats.push_back(concat({h, z}));
    }
    Tensor post = concat(posts, 0), prior = concat(priors, 0), feat = concat(feats, 0);
    // KL balancing with free bits of 1 nat, as DreamerV3.
    Tensor dyn = mean(maximum(kl_categorical(stop_gradient(post), prior), 1.0f));
    Tensor rep = mean(maximum(kl_categorical(post, stop_gradient(prior)), 1.0f));
    Tensor recon = add_scalar(dec(feat), 0.5f);
    Tensor rec_loss = scale(sum(squared_error(recon, obs)), 1.0f / static_cast<float>(B * T));
    Tensor cont_loss = mean(bce_with_logits(cont(feat), cont_target));
    return add(add(rec_loss, cont_loss), add(scale(dyn, 0.5f), scale(rep, 0.1f)));
  }

  // Multiply-adds x2 of every GEMM and convolution, forward + backward.
  double flops() const {
    const double n = static_cast<double>(p.batch) * p.seq;
    double fwd = 0, first_conv = 0;
    // Encoder and decoder convolutions.
    int res = p.image, c_in = 3, c_out = p.depth;
    bool first = true;
    while (res > 4) {
      const double out_pixels = n * (res / 2) * (res / 2);
      const double f = 2.0 * out_pixels * 16 * c_in * c_out;
      fwd += f;  // encoder conv
      if (first) first_conv = f;
      // The decoder's transposed conv mirrors it: same multiply-adds.
      fwd += 2.0 * out_pixels * 16 * (first ? 3 : c_in) * c_out;
      first = false;
      c_in = c_out;
      c_out *= 2;
      res /= 2;
    }
    const double embed = enc.embed_dim();
    const double feat = p.deter + stoch;
    fwd += 2.0 * n * feat * embed;                                     // decoder input
    fwd += 2.0 * n * ((stoch + kActions) * p.units);                   // img_in
    fwd += 2.0 * n * ((p.units + p.deter) * 3.0 * p.deter);            // GRU
    fwd += 2.0 * n * (p.deter * p.units + p.units * stoch);            // prior head
    fwd += 2.0 * n * ((p.deter + embed) * p.units + p.units * stoch);  // posterior head
    fwd += 2.0 * n * (feat * p.units + p.units * p.units + p.units);   // continuation head
    return 3.0 * fwd - first_conv;
  }

  const Preset& p;
  int stoch;
  ConvEncoder enc;
  Mlp img_in;
  GruCell gru;
  Mlp img_out, obs_out;
  ConvDecoder dec;
  Mlp cont;
};

}  // namespace

int main(int argc, char** argv) {
  std::string preset_name = "cpu";
  int threads = 2, iters = 3;
  bool skip_gemm = false;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    if (arg == "--preset" && i + 1 < argc) {
      preset_name = argv[++i];
    } else if (arg == "--threads" && i + 1 < argc) {
      threads = std::atoi(argv[++i]);
    } else if (arg == "--iters" && i + 1 < argc) {
      iters = std::atoi(argv[++i]);
    } else if (arg == "--skip-gemm") {
      skip_gemm = true;
    } else {
      std::fprintf(stderr,
                   "usage: nn_bench [--preset tiny|cpu|small] [--threads N] [--iters N] "
                   "[--skip-gemm]\n");
      return 2;
    }
  }
  const Preset* preset = nullptr;
  for (const Preset& p : kPresets)
    if (preset_name == p.name) preset = &p;
  if (preset == nullptr || threads < 1 || iters < 1) {
    std::fprintf(stderr, "unknown preset '%s' or bad --threads/--iters\n", preset_name.c_str());
    return 2;
  }
  set_threads(threads);
  std::printf("threads %d\n", threads);
  const double peak = skip_gemm ? 0.0 : gemm_peak();
  if (!skip_gemm) std::printf("gemm peak: %.1f GFLOP/s\n", peak);

  const Preset& p = *preset;
  one_hot_tail_bench(p);

  // (b) World-model update.
  Rng rng(0);
  ParamGroup group("world_model");
  WorldModel wm(p, group, rng);
  Adam adam(group, {.lr = 1e-4f, .eps = 1e-8f, .clip = 1000.0f});
  const int rows = p.batch * p.seq;
  std::vector<float> obs(static_cast<std::size_t>(rows) * p.image * p.image * 3);
  for (float& v : obs) v = rng.uniform();
  std::vector<float> act(static_cast<std::size_t>(rows) * kActions, 0.0f);
  for (int r = 0; r < rows; ++r) act[r * kActions + rng.below(kActions)] = 1.0f;
  std::vector<float> cont(static_cast<std::size_t>(rows), 1.0f);

  Graph& g = current_graph();
  std::vector<double> times, fwd_times, cpu_times, faults;
  std::size_t allocations_after_warmup = 0;
  float last_loss = 0;
  // Two warm-up updates: the first grows the arena, later ones reuse its blocks.
  constexpr int kWarmup = 2;
  for (int i = 0; i < iters + kWarmup; ++i) {
    const auto t0 = Clock::now();
    const double cpu0 = process_cpu_seconds();
    const double faults0 = page_faults();
    g.reset();
    Tensor loss = wm.loss(constant({rows, p.image, p.image, 3}, obs),
                          constant({rows, kActions}, act), constant({rows, 1}, cont), rng);
    const double fwd = seconds_since(t0);
    g.backward(loss);
    adam.step();
    const double total = seconds_since(t0);
    const double cpu = process_cpu_seconds() - cpu0;
    const double fault_count = page_faults() - faults0;
    last_loss = loss.item();
    std::printf("update %d: %.3f s wall, %.3f s cpu, %.0f page faults%s\n", i, total, cpu,
                fault_count, i < kWarmup ? " (warm-up)" : "");
    std::fflush(stdout);
    if (i < kWarmup) {
      allocations_after_warmup = g.arena_system_allocations();
      continue;
    }
    times.push_back(total);
    fwd_times.push_back(fwd);
    cpu_times.push_back(cpu);
    faults.push_back(fault_count);
  }
  const double sec = median(times);
  const double flops = wm.flops();
  std::printf(
      "preset=%s params=%lld B=%d T=%d loss=%.3f\n"
      "sec_per_update=%.3f (forward %.3f, backward+adam %.3f) cpu_sec_per_update=%.3f "
      "page_faults_per_update=%.0f frames_per_sec=%.0f\n"
      "flops_per_update=%.3e achieved=%.1f GFLOP/s",
      p.name, static_cast<long long>(group.numel()), p.batch, p.seq, last_loss, sec,
      median(fwd_times), sec - median(fwd_times), median(cpu_times), median(faults), rows / sec,
      flops, flops / sec / 1e9);
  if (peak > 0) std::printf(" = %.0f%% of gemm peak", 100.0 * flops / sec / 1e9 / peak);
  std::printf(
      "\narena=%.0f MB nodes=%zu arena_system_allocations: after warm-up %zu, after %d more "
      "updates %zu\n",
      g.arena_capacity_bytes() / 1e6, g.num_nodes(), allocations_after_warmup, iters,
      g.arena_system_allocations());
  return 0;
}
