// The engine's kernel layer: every matrix product (linear layers, and both convolutions as
// im2col + product, forward and backward) runs here, on oneDNN's matmul where the build has it
// (brgemm kernels chosen at run time for the CPU: AMX, AVX-512, AVX2) and on Eigen otherwise or for
// products too small for a primitive call to pay.
//
// Precision of the products' operands is process-wide:
//   - kFp32: fp32 operands and accumulation (the reference; gradient checks use it).
//   - kBf16: bf16 operands, fp32 accumulation, fp32 output. Parameters, gradients, optimiser
//     state and every other op stay fp32 (mixed precision with fp32 master weights). Only where
//     the CPU multiplies bf16 natively (AMX or AVX512_BF16, checked at run time).
//
//   nn::set_precision(nn::resolve_precision("auto"));   // bf16 where native, else fp32
//   INDRIVE_LOG(info) << nn::kernel_report();           // which path runs, and why
#pragma once

#include <cstdint>
#include <stdexcept>
#include <string>
#include <string_view>

namespace indrive::nn {

enum class Precision { kFp32, kBf16 };

class PrecisionError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

std::string_view to_string(Precision p);

// True where this CPU multiplies bf16 natively (oneDNN's effective ISA is avx512_core_bf16 or
// an AMX level; ONEDNN_MAX_CPU_ISA lowers it). Always false in a build without oneDNN.
bool bf16_supported();

// True where linear_one_hot_tail finds an input's ones eight columns at a time (AVX2, checked
// at run time); elsewhere it scans one column at a time. set_one_hot_scan_vectorised(false)
// takes the one-column path on any CPU (for tests of that path); true restores the check.
bool one_hot_scan_vectorised();
void set_one_hot_scan_vectorised(bool allowed);

// Whether linear_one_hot_tail gathers (the default) or runs the dense product like linear();
// for benchmarks that compare the two.
void set_gather_one_hot(bool on);
bool gather_one_hot();

// "fp32" and "bf16" as such; "auto" is bf16 where bf16_supported(), else fp32 (the agent times
// its own update in both instead: agent/precision_choice.h). Throws
// PrecisionError for any other text, and for "bf16" on a CPU without native bf16, saying what
// to set instead.
Precision resolve_precision(std::string_view text);

void set_precision(Precision p);
Precision precision();

// One line for the log: the kernel library and its version, the CPU ISA it runs, and the
// precision of the products and the one-hot scan, e.g. "kernels: oneDNN 2.6.3 on
// avx512_core_amx; products bf16 on AMX tiles (...); one-hot inputs scanned with AVX2".
std::string kernel_report();

// Whether products go to oneDNN (true where built with it) or stay on Eigen; for benchmarks
// that compare the two.
bool onednn_available();
void set_use_onednn(bool on);
bool use_onednn();

// Multiply-adds x2 of every product since the start of the process, over all threads: the
// benchmarks' FLOP count.
std::uint64_t gemm_flops();

namespace detail {

// How long an operand's values stay as they are, which decides whether its bf16 copy may be
// kept and reused by later products:
//   - kScratch: only for this product (im2col buffers); converted every time.
//   - kGraphValue: until the graph is reset or rewound (a node's value, a node's gradient
//     once its backward runs); converted once per graph and reused.
//   - kVersioned: while *version keeps its value (a parameter: Parameter::value() for writing
//     bumps it) and no graph is reset; converted once per version and graph (a rewind keeps
//     the copy).
enum class Lifetime { kScratch, kGraphValue, kVersioned };

// One operand of a product: logical (rows, cols); stored row-major as (rows, cols), or as
// (cols, rows) when `transposed`.
struct GemmOperand {
  const float* data;
  std::int64_t rows, cols;
  bool transposed;
  Lifetime lifetime = Lifetime::kScratch;
  const std::uint64_t* version = nullptr;  // kVersioned only
};

// Drops every kept bf16 copy of graph values, and with `reset` of parameters too:
// Graph::rewind() calls it with false, Graph::reset() with true.
void forget_graph_conversions(bool reset);

// dst (m, n), row-major and contiguous, = a * b, or += when `accumulate`. Single products run
// on the calling thread when called inside a parallel region.
void gemm(float* dst, GemmOperand a, GemmOperand b, bool accumulate);

}  // namespace detail

}  // namespace indrive::nn
