// The kernel layer (indrive/nn/kernels.h): matrix products on oneDNN's matmul, with
// primitives created once per shape and reused, or on Eigen's GEMM.
#include "indrive/nn/kernels.h"

#include <omp.h>

#include <algorithm>
#include <atomic>
#include <cstring>
#include <memory>
#include <string>
#include <unordered_map>
#include <vector>

#include "indrive/basics/check.h"
#include "indrive/nn/tensor.h"

#if INDRIVE_WITH_ONEDNN
#include <oneapi/dnnl/dnnl.hpp>
#endif

namespace indrive::nn {
namespace {

std::atomic<Precision> g_precision{Precision::kFp32};
std::atomic<bool> g_use_onednn{INDRIVE_WITH_ONEDNN != 0};
std::atomic<bool> g_gather_one_hot{true};        // linear_one_hot_tail gathers
std::atomic<bool> g_one_hot_scan_allowed{true};  // its AVX2 scan, where the CPU has it
std::atomic<std::uint64_t> g_flops{0};
// Bumped by every Graph::reset() and rewind(): kept bf16 copies of graph values older than the
// current generation are stale.
std::atomic<std::uint64_t> g_graph_generation{1};
// Bumped by every Graph::reset() only: kept copies of parameters are trusted by their version
// within one graph, so a rewind (scoring imagined states in chunks) does not convert the same
// weights again for every chunk.
std::atomic<std::uint64_t> g_reset_generation{1};

#if INDRIVE_WITH_ONEDNN
// Products below this many multiply-adds stay on Eigen in fp32 whatever the precision: a
// primitive call (memory objects, argument map, dispatch, bf16 conversion) costs a few
// microseconds, which such a product does not repay.
constexpr std::int64_t kOneDnnMinWork = std::int64_t{1} << 15;
#endif

// ---- Eigen -------------------------------------------------------------------------------

// Products with at least this many multiply-adds are split over threads; smaller ones run on
// the calling thread, because a parallel region costs more than it saves (and much more when
// the machine is oversubscribed and idle threads spin).
constexpr std::int64_t kParallelGemmWork = std::int64_t{1} << 22;

// Runs Eigen's GEMM single-threaded: the engine splits large products itself (below), so that
// the thread count is ours to set and small products never open a parallel region.
void eigen_single_threaded() {
  static const bool once = (Eigen::setNbThreads(1), true);
  (void)once;
}

// Large products are split over output rows (or columns when there are few rows).
template <typename A, typename B>
void eigen_gemm(MatrixMap dst, const A& a, const B& b, bool accumulate) {
  eigen_single_threaded();
  const std::int64_t m = dst.rows(), n = dst.cols(), k = a.cols();
  const int threads = omp_in_parallel() ? 1 : omp_get_max_threads();
  if (threads == 1 || m * n * k < kParallelGemmWork) {
    if (accumulate)
      dst.noalias() += a * b;
    else
      dst.noalias() = a * b;
    return;
  }
  const bool by_rows = m >= 64 * threads || m >= n;
  const std::int64_t extent = by_rows ? m : n;
  // A few parts per thread, handed out dynamically, so that a thread delayed by other jobs on
  // the machine does not hold the rest at the barrier. Parts split on multiples of 16 so that
  // each keeps full SIMD panels; every output element is computed by one part with the same
  // code whichever thread runs it, so results do not depend on the schedule.
  const std::int64_t parts =
      std::max<std::int64_t>(1, std::min<std::int64_t>(4 * threads, extent / 64));
  const std::int64_t part = ((extent + parts - 1) / parts + 15) / 16 * 16;
#pragma omp parallel for schedule(dynamic, 1) num_threads(threads)
  for (std::int64_t t = 0; t < parts; ++t) {
    const std::int64_t begin = std::min(extent, t * part);
    const std::int64_t len = std::min(extent, begin + part) - begin;
    if (len <= 0) continue;
    if (by_rows) {
      if (accumulate)
        dst.middleRows(begin, len).noalias() += a.middleRows(begin, len) * b;
      else
        dst.middleRows(begin, len).noalias() = a.middleRows(begin, len) * b;
    } else {
      if (accumulate)
        dst.middleCols(begin, len).noalias() += a * b.middleCols(begin, len);
      else
        dst.middleCols(begin, len).noalias() = a * b.middleCols(begin, len);
    }
  }
}

void eigen_gemm(float* dst, const detail::GemmOperand& a, const detail::GemmOperand& b,
                bool accumulate) {
  MatrixMap d(dst, a.rows, b.cols);
  // A transposed operand is a transposed view of its storage; no copy.
  const ConstMatrixMap as(a.data, a.transposed ? a.cols : a.rows, a.transposed ? a.rows : a.cols);
  const ConstMatrixMap bs(b.data, b.transposed ? b.cols : b.rows, b.transposed ? b.rows : b.cols);
  if (!a.transposed && !b.transposed) eigen_gemm(d, as, bs, accumulate);
  if (!a.transposed && b.transposed) eigen_gemm(d, as, bs.transpose(), accumulate);
  if (a.transposed && !b.transposed) eigen_gemm(d, as.transpose(), bs, accumulate);
  if (a.transposed && b.transposed) eigen_gemm(d, as.transpose(), bs.transpose(), accumulate);
}

// ---- oneDNN ------------------------------------------------------------------------------

#if INDRIVE_WITH_ONEDNN

dnnl::engine& cpu_engine() {
  static dnnl::engine engine(dnnl::engine::kind::cpu, 0);
  return engine;
}

bool isa_has(dnnl::cpu_isa isa, dnnl::cpu_isa feature) {
  const auto v = static_cast<unsigned>(isa), f = static_cast<unsigned>(feature);
  return (v & f) == f;
}

const char* isa_name(dnnl::cpu_isa isa) {
  using I = dnnl::cpu_isa;
  if (isa_has(isa, I::avx512_core_amx)) return "avx512_core_amx";
  if (isa_has(isa, I::avx512_core_bf16)) return "avx512_core_bf16";
  if (isa_has(isa, I::avx512_core_vnni)) return "avx512_core_vnni";
  if (isa_has(isa, I::avx512_core)) return "avx512_core";
  if (isa_has(isa, I::avx2)) return "avx2";
  if (isa_has(isa, I::avx)) return "avx";
  if (isa_has(isa, I::sse41)) return "sse41";
  return "generic";
}

// Primitives take their scratch memory from the calling thread's buffer (below) instead of
// allocating it on every execution, which would fault fresh pages in each time.
dnnl::primitive_attr user_scratchpad() {
  dnnl::primitive_attr attr;
  attr.set_scratchpad_mode(dnnl::scratchpad_mode::user);
  return attr;
}

// A cached product: the primitive and the descriptors its memory objects are made from.
struct MatmulEntry {
  dnnl::matmul primitive;
  dnnl::memory::desc a, b, c, scratchpad;
};

struct MatmulKey {
  std::int64_t m, n, k;
  bool ta, tb, accumulate, bf16;
  int threads;
  bool operator==(const MatmulKey&) const = default;
};

struct MatmulKeyHash {
  std::size_t operator()(const MatmulKey& key) const {
    std::size_t h = static_cast<std::size_t>(key.m) * 0x9E3779B97F4A7C15ull;
    h ^= static_cast<std::size_t>(key.n) + 0x7F4A7C15ull + (h << 6) + (h >> 2);
    h ^= static_cast<std::size_t>(key.k) + 0x9E37ull + (h << 6) + (h >> 2);
    return h ^ (static_cast<std::size_t>(key.ta) | key.tb << 1 | key.accumulate << 2 |
                key.bf16 << 3 | static_cast<std::size_t>(key.threads) << 4);
  }
};

// When a copy of an operand was made: the graph generation, and for a parameter its version.
// A copy serves later products only while both are unchanged. Parameters are usually written
// between graphs (an optimiser step, then the next update's reset), but code may also write
// through a span it took earlier, so the version alone is not trusted across a reset.
struct Stamp {
  std::uint64_t generation = 0, version = 0;
  bool valid() const { return generation != 0; }
  bool operator==(const Stamp&) const = default;
};

Stamp stamp_of(detail::Lifetime lifetime, const std::uint64_t* version) {
  if (lifetime == detail::Lifetime::kScratch) return {};
  if (lifetime == detail::Lifetime::kVersioned)
    return {g_reset_generation.load(std::memory_order_relaxed), *version};
  return {g_graph_generation.load(std::memory_order_relaxed), 0};
}

// A grow-only bf16 buffer, left uninitialised (every use overwrites what it reads).
class Staging {
 public:
  // At least n elements; a buffer that must grow takes at least `floor` at once, so that the
  // few buffers used in turn settle at their largest size after one growth each.
  std::uint16_t* get(std::int64_t n, std::int64_t floor = 0) {
    if (n > capacity_) {
      capacity_ = std::max(n, floor);
      data_.reset(new std::uint16_t[static_cast<std::size_t>(capacity_)]);
    }
    return data_.get();
  }
  std::uint16_t* data() const { return data_.get(); }

 private:
  std::unique_ptr<std::uint16_t[]> data_;
  std::int64_t capacity_ = 0;
};

// A bf16 copy of an operand's storage, with the stamp it was made at.
struct Kept {
  const float* data = nullptr;
  std::int64_t n = 0;
  Stamp stamp;
  Staging bf16;
};

// Graph values kept at once: enough for an input shared by the K ensemble members, or an
// activation used again by the next products; older copies are overwritten in turn.
constexpr int kKeptGraphValues = 8;

// Per thread: a stream, the primitives made on this thread, bf16 staging buffers and kept
// copies. The engine is shared. Primitives are made per thread count because oneDNN
// decomposes the work for the threads it expects when the primitive is created.
struct ThreadContext {
  dnnl::stream stream{cpu_engine()};
  std::unordered_map<MatmulKey, MatmulEntry, MatmulKeyHash> matmuls;
  std::unordered_map<std::int64_t, dnnl::reorder> to_bf16;  // by element count
  Staging a16, b16;
  std::int64_t largest_graph_value = 0;
  std::vector<std::uint8_t> scratchpad;               // grows to the largest primitive's need
  std::unordered_map<const float*, Kept> parameters;  // by storage
  Kept graph_values[kKeptGraphValues];
  int next_graph_value = 0;
};

ThreadContext& context() {
  thread_local ThreadContext ctx;
  return ctx;
}

// The thread's scratch buffer as the memory a primitive with scratchpad `desc` wants.
dnnl::memory scratchpad_for(ThreadContext& ctx, const dnnl::memory::desc& desc) {
  const std::size_t bytes = desc.get_size();
  if (ctx.scratchpad.size() < bytes) ctx.scratchpad.resize(bytes);
  return dnnl::memory(desc, cpu_engine(), ctx.scratchpad.data());
}

// The descriptor of an operand's logical (rows, cols) shape over its storage.
dnnl::memory::desc operand_desc(const detail::GemmOperand& x, dnnl::memory::data_type type) {
  const dnnl::memory::dims dims = {x.rows, x.cols};
  const dnnl::memory::dims strides =
      x.transposed ? dnnl::memory::dims{1, x.rows} : dnnl::memory::dims{x.cols, 1};
  return dnnl::memory::desc(dims, type, strides);
}

const MatmulEntry& matmul_for(ThreadContext& ctx, const detail::GemmOperand& a,
                              const detail::GemmOperand& b, bool accumulate, bool bf16,
                              int threads) {
  const MatmulKey key{a.rows,       b.cols,     a.cols, a.transposed,
                      b.transposed, accumulate, bf16,   threads};
  auto it = ctx.matmuls.find(key);
  if (it != ctx.matmuls.end()) return it->second;
  using dt = dnnl::memory::data_type;
  const dt in = bf16 ? dt::bf16 : dt::f32;
  MatmulEntry entry;
  entry.a = operand_desc(a, in);
  entry.b = operand_desc(b, in);
  entry.c = dnnl::memory::desc({a.rows, b.cols}, dt::f32, dnnl::memory::dims{b.cols, 1});
  dnnl::primitive_attr attr = user_scratchpad();
  if (accumulate) {
    dnnl::post_ops ops;
    ops.append_sum(1.0f);
    attr.set_post_ops(ops);
  }
  const dnnl::matmul::primitive_desc pd(dnnl::matmul::desc(entry.a, entry.b, entry.c), attr,
                                        cpu_engine());
  entry.primitive = dnnl::matmul(pd);
  entry.scratchpad = pd.scratchpad_desc();
  return ctx.matmuls.emplace(key, std::move(entry)).first->second;
}

// Copies n floats into bf16 (round to nearest even) with oneDNN's reorder.
void convert_to_bf16(ThreadContext& ctx, const float* src, std::int64_t n, std::uint16_t* dst) {
  using dt = dnnl::memory::data_type;
  const dnnl::memory::desc f32({n}, dt::f32, dnnl::memory::dims{1});
  const dnnl::memory::desc b16({n}, dt::bf16, dnnl::memory::dims{1});
  auto it = ctx.to_bf16.find(n);
  if (it == ctx.to_bf16.end()) {
    it = ctx.to_bf16
             .emplace(n, dnnl::reorder(
                             dnnl::reorder::primitive_desc(cpu_engine(), f32, cpu_engine(), b16)))
             .first;
  }
  dnnl::memory from(f32, cpu_engine(), const_cast<float*>(src));
  dnnl::memory to(b16, cpu_engine(), dst);
  it->second.execute(ctx.stream, from, to);
}

// The operand in bf16: a kept copy where its lifetime allows and one is current, else a new
// conversion (kept, or in `scratch`).
const std::uint16_t* bf16_operand(ThreadContext& ctx, const detail::GemmOperand& x,
                                  Staging& scratch) {
  const std::int64_t n = x.rows * x.cols;
  const Stamp stamp = stamp_of(x.lifetime, x.version);
  Kept* kept = nullptr;
  if (x.lifetime == detail::Lifetime::kVersioned) {
    kept = &ctx.parameters[x.data];
  } else if (x.lifetime == detail::Lifetime::kGraphValue) {
    for (Kept& k : ctx.graph_values) {
      if (k.data == x.data && k.n == n && k.stamp == stamp) return k.bf16.data();
    }
    kept = &ctx.graph_values[ctx.next_graph_value];
    ctx.next_graph_value = (ctx.next_graph_value + 1) % kKeptGraphValues;
  }
  if (kept == nullptr) {
    std::uint16_t* out = scratch.get(n);
    convert_to_bf16(ctx, x.data, n, out);
    return out;
  }
  if (kept->data == x.data && kept->n == n && kept->stamp == stamp && kept->bf16.data())
    return kept->bf16.data();
  if (x.lifetime == detail::Lifetime::kGraphValue)
    ctx.largest_graph_value = std::max(ctx.largest_graph_value, n);
  std::uint16_t* out =
      kept->bf16.get(n, x.lifetime == detail::Lifetime::kGraphValue ? ctx.largest_graph_value : 0);
  convert_to_bf16(ctx, x.data, n, out);
  kept->data = x.data, kept->n = n, kept->stamp = stamp;
  return out;
}

void onednn_gemm(float* dst, const detail::GemmOperand& a, const detail::GemmOperand& b,
                 bool accumulate, bool bf16) {
  ThreadContext& ctx = context();
  // As on the Eigen path, a small product runs on the calling thread: oneDNN takes its thread
  // count from OpenMP, so it is lowered to 1 around the primitive (and restored after).
  const int max_threads = omp_in_parallel() ? 1 : omp_get_max_threads();
  const bool small = a.rows * b.cols * a.cols < kParallelGemmWork;
  const int threads = small ? 1 : max_threads;
  struct OmpThreads {
    int restore;
    explicit OmpThreads(int set, int was) : restore(set != was ? was : 0) {
      if (restore) omp_set_num_threads(set);
    }
    ~OmpThreads() {
      if (restore) omp_set_num_threads(restore);
    }
  } omp_threads(threads, max_threads);
  const MatmulEntry& mm = matmul_for(ctx, a, b, accumulate, bf16, threads);
  const void* ap = a.data;
  const void* bp = b.data;
  if (bf16) {
    ap = bf16_operand(ctx, a, ctx.a16);
    bp = bf16_operand(ctx, b, ctx.b16);
  }
  dnnl::memory am(mm.a, cpu_engine(), const_cast<void*>(ap));
  dnnl::memory bm(mm.b, cpu_engine(), const_cast<void*>(bp));
  dnnl::memory cm(mm.c, cpu_engine(), dst);
  mm.primitive.execute(ctx.stream, {{DNNL_ARG_SRC, am},
                                    {DNNL_ARG_WEIGHTS, bm},
                                    {DNNL_ARG_DST, cm},
                                    {DNNL_ARG_SCRATCHPAD, scratchpad_for(ctx, mm.scratchpad)}});
  ctx.stream.wait();
}

#endif  // INDRIVE_WITH_ONEDNN

}  // namespace

std::string_view to_string(Precision p) { return p == Precision::kBf16 ? "bf16" : "fp32"; }

bool bf16_supported() {
#if INDRIVE_WITH_ONEDNN
  static const bool supported =
      isa_has(dnnl::get_effective_cpu_isa(), dnnl::cpu_isa::avx512_core_bf16);
  return supported;
#else
  return false;
#endif
}

void set_gather_one_hot(bool on) { g_gather_one_hot = on; }
bool gather_one_hot() { return g_gather_one_hot.load(std::memory_order_relaxed); }

bool one_hot_scan_vectorised() {
#if defined(__x86_64__)
  static const bool vectorised = __builtin_cpu_supports("avx2") && __builtin_cpu_supports("bmi");
  return vectorised && g_one_hot_scan_allowed.load(std::memory_order_relaxed);
#else
  return false;
#endif
}

void set_one_hot_scan_vectorised(bool allowed) { g_one_hot_scan_allowed = allowed; }

Precision resolve_precision(std::string_view text) {
  if (text == "fp32") return Precision::kFp32;
  if (text == "auto") return bf16_supported() ? Precision::kBf16 : Precision::kFp32;
  if (text == "bf16") {
    if (!bf16_supported()) {
      throw PrecisionError(
          "precision bf16 needs a CPU that multiplies bf16 natively (AMX or AVX512_BF16) and a "
          "build with oneDNN; this one has not (" +
          kernel_report() + "): set precision to fp32 or auto");
    }
    return Precision::kBf16;
  }
  throw PrecisionError("precision '" + std::string(text) + "': use one of auto, fp32, bf16");
}

void set_precision(Precision p) {
  INDRIVE_CHECK(p == Precision::kFp32 || bf16_supported())
      << "bf16 products on a CPU without native bf16; resolve_precision says what to set";
  g_precision = p;
}

Precision precision() { return g_precision; }

std::string kernel_report() {
  std::string out = "kernels: ";
#if INDRIVE_WITH_ONEDNN
  const dnnl_version_t* v = dnnl_version();
  const dnnl::cpu_isa isa = dnnl::get_effective_cpu_isa();
  out += "oneDNN " + std::to_string(v->major) + "." + std::to_string(v->minor) + "." +
         std::to_string(v->patch) + " on " + isa_name(isa);
  if (!g_use_onednn) out += " (off: Eigen GEMM)";
  out += "; products ";
  if (precision() == Precision::kBf16) {
    out +=
        isa_has(isa, dnnl::cpu_isa::avx512_core_amx) ? "bf16 on AMX tiles" : "bf16 on AVX512_BF16";
    out += " (fp32 accumulation, fp32 master weights)";
  } else {
    out += "fp32";
    if (!bf16_supported()) out += " (no native bf16 on this CPU)";
  }
#else
  out += "Eigen GEMM (built without oneDNN); products fp32";
#endif
  out += one_hot_scan_vectorised() ? "; one-hot inputs scanned with AVX2"
                                   : "; one-hot inputs scanned one column at a time";
  return out;
}

bool onednn_available() { return INDRIVE_WITH_ONEDNN != 0; }
void set_use_onednn(bool on) { g_use_onednn = on && onednn_available(); }
bool use_onednn() { return g_use_onednn; }

std::uint64_t gemm_flops() { return g_flops.load(std::memory_order_relaxed); }

namespace detail {

void forget_graph_conversions(bool reset) {
  g_graph_generation.fetch_add(1, std::memory_order_relaxed);
  if (reset) g_reset_generation.fetch_add(1, std::memory_order_relaxed);
}

std::uint64_t next_parameter_version() {
  static std::atomic<std::uint64_t> counter{1};
  return counter.fetch_add(1, std::memory_order_relaxed);
}

void gemm(float* dst, GemmOperand a, GemmOperand b, bool accumulate) {
  INDRIVE_CHECK_EQ(a.cols, b.rows)
      << "product of (" << a.rows << ", " << a.cols << ") and (" << b.rows << ", " << b.cols << ")";
  const std::int64_t m = a.rows, n = b.cols, k = a.cols;
  if (m == 0 || n == 0) return;
  if (k == 0) {
    if (!accumulate) std::memset(dst, 0, sizeof(float) * m * n);
    return;
  }
  g_flops.fetch_add(static_cast<std::uint64_t>(2 * m * n * k), std::memory_order_relaxed);
#if INDRIVE_WITH_ONEDNN
  const bool bf16 = g_precision.load(std::memory_order_relaxed) == Precision::kBf16;
  if (g_use_onednn.load(std::memory_order_relaxed) && m * n * k >= kOneDnnMinWork) {
    onednn_gemm(dst, a, b, accumulate, bf16);
    return;
  }
#endif
  eigen_gemm(dst, a, b, accumulate);
}

}  // namespace detail
}  // namespace indrive::nn
