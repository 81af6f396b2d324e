// The kernel layer: oneDNN products against Eigen's in fp32, bf16 products within the rounding
// of their operands, the kept bf16 copies following every change of their source, products
// inside a parallel region, the FLOP count and the precision setting's errors.
#include "indrive/nn/kernels.h"

#include <gtest/gtest.h>
#include <omp.h>

#include <cmath>
#include <span>
#include <vector>

#include "indrive/nn/nn.h"

namespace indrive::nn {
namespace {

// Restores the process-wide settings a test changes.
class KernelsTest : public ::testing::Test {
 protected:
  void SetUp() override {
    saved_precision_ = precision();
    saved_onednn_ = use_onednn();
    set_threads(1);
  }
  void TearDown() override {
    set_precision(saved_precision_);
    set_use_onednn(saved_onednn_);
    current_graph().reset();
  }

 private:
  Precision saved_precision_ = Precision::kFp32;
  bool saved_onednn_ = true;
};

std::vector<float> random_values(std::int64_t n, std::uint64_t seed) {
  Rng rng(seed);
  std::vector<float> v(static_cast<std::size_t>(n));
  for (float& x : v) x = rng.normal();
  return v;
}

// dst = a * b (+ dst) with the kernel layer, where a (m, k) and b (k, n) are stored transposed
// when asked.
std::vector<float> product(std::int64_t m, std::int64_t n, std::int64_t k, bool ta, bool tb,
                           bool accumulate, const std::vector<float>& a,
                           const std::vector<float>& b, std::vector<float> dst) {
  detail::gemm(dst.data(), {a.data(), m, k, ta}, {b.data(), k, n, tb}, accumulate);
  return dst;
}

// Largest |x - y| relative to the largest |y|.
double relative_error(const std::vector<float>& x, const std::vector<float>& y) {
  double worst = 0, scale = 1e-12;
  for (std::size_t i = 0; i < x.size(); ++i) {
    worst = std::max(worst, static_cast<double>(std::fabs(x[i] - y[i])));
    scale = std::max(scale, static_cast<double>(std::fabs(y[i])));
  }
  return worst / scale;
}

struct Case {
  std::int64_t m, n, k;
};
// Shapes of the presets' products: RSSM steps (few rows), heads over a batch, im2col panels,
// and one below the size at which products leave Eigen.
const Case kCases[] = {{16, 768, 1289}, {1024, 256, 1280}, {4096, 16, 48}, {33, 65, 17}, {8, 9, 4}};

TEST_F(KernelsTest, OneDnnAgreesWithEigenInFp32ForEveryLayout) {
  if (!onednn_available()) GTEST_SKIP() << "built without oneDNN (INDRIVE_ONEDNN=OFF)";
  set_precision(Precision::kFp32);
  for (const Case& c : kCases) {
    const auto a = random_values(c.m * c.k, 1), b = random_values(c.k * c.n, 2);
    const auto init = random_values(c.m * c.n, 3);
    for (int layout = 0; layout < 8; ++layout) {
      const bool ta = layout & 1, tb = layout & 2, acc = layout & 4;
      set_use_onednn(false);
      const auto ref = product(c.m, c.n, c.k, ta, tb, acc, a, b, init);
      set_use_onednn(true);
      const auto got = product(c.m, c.n, c.k, ta, tb, acc, a, b, init);
      EXPECT_LT(relative_error(got, ref), 1e-5)
          << c.m << "x" << c.n << "x" << c.k << " ta=" << ta << " tb=" << tb << " acc=" << acc;
    }
  }
}

TEST_F(KernelsTest, Bf16ProductsStayWithinTheRoundingOfTheirOperands) {
  if (!bf16_supported()) GTEST_SKIP() << "no native bf16 here: " << kernel_report();
  for (const Case& c : kCases) {
    const auto a = random_values(c.m * c.k, 4), b = random_values(c.k * c.n, 5);
    const auto init = random_values(c.m * c.n, 6);
    for (int layout = 0; layout < 8; ++layout) {
      const bool ta = layout & 1, tb = layout & 2, acc = layout & 4;
      set_precision(Precision::kFp32);
      const auto ref = product(c.m, c.n, c.k, ta, tb, acc, a, b, init);
      set_precision(Precision::kBf16);
      const auto got = product(c.m, c.n, c.k, ta, tb, acc, a, b, init);
      // bf16 keeps 8 bits of mantissa (relative rounding 2^-9 per operand); with fp32
      // accumulation of k terms of random sign the error of the sum grows like sqrt(k), far
      // below 1% of the largest element for these sizes.
      EXPECT_LT(relative_error(got, ref), 1e-2)
          << c.m << "x" << c.n << "x" << c.k << " ta=" << ta << " tb=" << tb << " acc=" << acc;
      if (c.m * c.n * c.k >= (1 << 15)) {
        EXPECT_GT(relative_error(got, ref), 0.0) << "ran fp32";
      }
    }
  }
}

TEST_F(KernelsTest, AKeptBf16CopyOfAParameterFollowsEveryWrite) {
  if (!bf16_supported()) GTEST_SKIP() << "no native bf16 here: " << kernel_report();
  set_precision(Precision::kBf16);
  ParamGroup group("g");
  Parameter& w = group.add("w", {256, 128});
  const auto first = random_values(256 * 128, 7);
  std::copy(first.begin(), first.end(), w.value().begin());
  const auto x_values = random_values(64 * 256, 8);
  const auto run = [&] {
    current_graph().reset();
    Tensor y = matmul(constant({64, 256}, x_values), w.tensor());
    return std::vector<float>(y.values().begin(), y.values().end());
  };
  const auto y1 = run();
  const auto y1_again = run();
  EXPECT_EQ(y1, y1_again);
  // An optimiser-style write in place: the next product must see it.
  for (float& v : w.value()) v = -v;
  const auto y2 = run();
  for (std::size_t i = 0; i < y1.size(); ++i) ASSERT_EQ(y2[i], -y1[i]) << i;
  // Within one graph (no reset between), a write through value() is seen by the next product:
  // only the parameter's version tells.
  current_graph().reset();
  const Tensor x = constant({64, 256}, x_values);
  const Tensor before = matmul(x, w.tensor());
  for (float& v : w.value()) v = -v;  // back to the first values
  const Tensor after = matmul(x, w.tensor());
  for (std::int64_t i = 0; i < before.numel(); ++i) {
    ASSERT_EQ(before.data()[i], y2[static_cast<std::size_t>(i)]) << i;
    ASSERT_EQ(after.data()[i], y1[static_cast<std::size_t>(i)]) << i;
  }
  for (float& v : w.value()) v = -v;
  // A write through a span taken before the last product (as gradient checks write) is seen
  // from the next graph on.
  const std::span<float> held = w.value();
  EXPECT_EQ(run(), y2);
  for (float& v : held) v = -v;
  EXPECT_EQ(run(), y1);
}

TEST_F(KernelsTest, AKeptBf16CopyOfAGraphValueEndsWithTheGraph) {
  if (!bf16_supported()) GTEST_SKIP() << "no native bf16 here: " << kernel_report();
  set_precision(Precision::kBf16);
  const auto w_values = random_values(256 * 128, 9);
  const auto x1 = random_values(64 * 256, 10), x2 = random_values(64 * 256, 11);
  const auto run = [&](const std::vector<float>& x) {
    current_graph().reset();  // the next constant lands where the last one was
    Tensor y = matmul(constant({64, 256}, x), constant({256, 128}, w_values));
    return std::vector<float>(y.values().begin(), y.values().end());
  };
  const auto y1 = run(x1);
  const auto y2 = run(x2);
  set_precision(Precision::kFp32);
  EXPECT_LT(relative_error(y1, run(x1)), 1e-2);
  EXPECT_LT(relative_error(y2, run(x2)), 1e-2);
  // The same within a scratch region that is rewound.
  set_precision(Precision::kBf16);
  current_graph().reset();
  NoGradGuard no_grad;
  const Tensor w = constant({256, 128}, w_values);
  const Graph::Mark mark = current_graph().mark();
  Tensor a = matmul(constant({64, 256}, x1), w);
  const std::vector<float> ya(a.values().begin(), a.values().end());
  current_graph().rewind(mark);
  Tensor b = matmul(constant({64, 256}, x2), w);
  const std::vector<float> yb(b.values().begin(), b.values().end());
  EXPECT_EQ(ya, y1);
  EXPECT_EQ(yb, y2);
}

TEST_F(KernelsTest, ProductsInsideAParallelRegionRunOnTheirOwnThread) {
  const auto a = random_values(512 * 300, 12), b = random_values(300 * 200, 13);
  const auto init = std::vector<float>(512 * 200, 0.0f);
  set_use_onednn(false);
  const auto ref = product(512, 200, 300, false, false, false, a, b, init);
  set_use_onednn(true);
  std::vector<std::vector<float>> got(4);
#pragma omp parallel for num_threads(2)
  for (int i = 0; i < 4; ++i) got[i] = product(512, 200, 300, false, false, false, a, b, init);
  for (const auto& g : got) EXPECT_LT(relative_error(g, ref), 1e-5);
}

TEST_F(KernelsTest, CountsTwoFlopsPerMultiplyAdd) {
  const auto a = random_values(20 * 30, 14), b = random_values(30 * 40, 15);
  const std::uint64_t before = gemm_flops();
  product(20, 40, 30, false, false, false, a, b, std::vector<float>(20 * 40));
  EXPECT_EQ(gemm_flops() - before, 2u * 20 * 40 * 30);
}

TEST_F(KernelsTest, PrecisionTextsAndTheirErrors) {
  EXPECT_EQ(resolve_precision("fp32"), Precision::kFp32);
  EXPECT_EQ(resolve_precision("auto"), bf16_supported() ? Precision::kBf16 : Precision::kFp32);
  EXPECT_THROW(resolve_precision("fp16"), PrecisionError);
  try {
    resolve_precision("half");
    FAIL() << "no error";
  } catch (const PrecisionError& e) {
    EXPECT_NE(std::string(e.what()).find("auto, fp32, bf16"), std::string::npos) << e.what();
  }
  if (!bf16_supported()) {
    try {
      resolve_precision("bf16");
      FAIL() << "bf16 accepted without native bf16";
    } catch (const PrecisionError& e) {
      EXPECT_NE(std::string(e.what()).find("set precision to fp32 or auto"), std::string::npos);
    }
  }
  EXPECT_NE(kernel_report().find("kernels: "), std::string::npos);
  // The report also says how one-hot inputs are scanned, and the CPU check agrees with it.
  EXPECT_NE(kernel_report().find(one_hot_scan_vectorised() ? "one-hot inputs scanned with AVX2"
                                                           : "one column at a time"),
            std::string::npos)
      << kernel_report();
}

}  // namespace
}  // namespace indrive::nn
