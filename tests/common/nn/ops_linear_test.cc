// Tests of ops_linear.cc: products (matmul, linear) and the one-hot tail gathered instead of
// multiplied.
#include "ops_test_support.h"

namespace indrive::nn {
namespace {

TEST_F(OpsTest, MatmulAndLinearGradients) {
  Parameter& x = input("x", {5, 7});
  Parameter& w = input("w", {7, 3});
  Parameter& b = input("b", {3});
  EXPECT_EQ(check("matmul", [&] { return matmul(x.tensor(), w.tensor()); }), 0);
  EXPECT_EQ(check("linear", [&] { return linear(x.tensor(), w.tensor(), b.tensor()); }), 0);
}

TEST_F(OpsTest, MatmulValuesMatchLoops) {
  Parameter& x = input("x", {2, 3, 4});
  Parameter& w = input("w", {4, 5});
  Tensor y = matmul(x.tensor(), w.tensor());
  ASSERT_EQ(y.shape(), (Shape{2, 3, 5}));
  for (int r = 0; r < 6; ++r)
    for (int c = 0; c < 5; ++c) {
      float expect = 0;
      for (int k = 0; k < 4; ++k) expect += x.value()[r * 4 + k] * w.value()[k * 5 + c];
      EXPECT_NEAR(y.data()[r * 5 + c], expect, 1e-5f);
    }
}

// linear_one_hot_tail against linear on the same input: x is `dense` random columns, then
// `groups` one-hot blocks of `classes`, then an action block of 9 that is all zeros in every
// fifth row (no action yet). Returns the largest difference over the values and the gradients
// of x, w and b (a weighted sum of the output as the loss).
class OneHotTailTest : public OpsTest {
 protected:
  float largest_difference(std::int64_t rows, int dense, int groups, int classes, std::int64_t cols,
                           std::int64_t from) {
    const int k = dense + groups * classes + 9;
    const std::string at = std::to_string(calls_++);
    Parameter& x = input("x" + at, {rows, k});
    Parameter& w = input("w" + at, {k, cols});
    Parameter& b = input("b" + at, {cols});
    Parameter& r = input("r" + at, {rows, cols});
    std::span<float> xv = x.value();
    for (std::int64_t i = 0; i < rows; ++i) {
      float* row = xv.data() + i * k;
      std::fill(row + dense, row + k, 0.0f);
      for (int g = 0; g < groups; ++g) row[dense + g * classes + (i * 7 + g * 3) % classes] = 1.0f;
      if (i % 5 != 0) row[dense + groups * classes + i % 9] = 1.0f;
    }
    auto run = [&](bool gather) {
      current_graph().reset();
      in_.zero_grad();
      Tensor y = gather ? linear_one_hot_tail(x.tensor(), w.tensor(), b.tensor(), from)
                        : linear(x.tensor(), w.tensor(), b.tensor());
      current_graph().backward(sum(mul(y, stop_gradient(r.tensor()))));
      std::vector<float> out(y.data(), y.data() + y.numel());
      for (Parameter* p : {&x, &w, &b}) out.insert(out.end(), p->grad().begin(), p->grad().end());
      return out;
    };
    const std::vector<float> dense_run = run(false), gathered = run(true);
    EXPECT_EQ(dense_run.size(), gathered.size());
    float worst = 0;
    for (std::size_t i = 0; i < dense_run.size(); ++i)
      worst = std::max(worst, std::fabs(dense_run[i] - gathered[i]));
    return worst;
  }
  int calls_ = 0;
};

TEST_F(OneHotTailTest, GathersTheSameValuesAndGradientsAsTheProduct) {
  // A model state [deter, stoch] + action: dense part, then one-hot columns.
  EXPECT_LT(largest_difference(37, 8, 3, 8, 70, 8), 1e-4f);
  // The same with the scan that reads one column at a time (CPUs without AVX2).
  set_one_hot_scan_vectorised(false);
  EXPECT_LT(largest_difference(37, 8, 3, 8, 70, 8), 1e-4f);
  set_one_hot_scan_vectorised(true);
  // [stoch, action] (the RSSM's input): one-hot from the first column.
  EXPECT_LT(largest_difference(21, 0, 4, 4, 5, 0), 1e-4f);
  // A tail that starts inside the dense part: those columns are taken as dense (they hold
  // neither only zeros nor only ones), so the op runs the plain product.
  EXPECT_LT(largest_difference(11, 6, 2, 8, 9, 3), 1e-4f);
  // No one-hot columns at all (from = k).
  EXPECT_LT(largest_difference(9, 4, 1, 4, 6, 4 + 4 + 9), 1e-4f);
}

TEST_F(OneHotTailTest, LargeInputsSplitOverThreadsMatchTheProduct) {
  // Enough rows and columns that the gather (rows) and the weight gradient (column blocks)
  // run in parallel with two threads.
  const int saved = threads();
  set_threads(2);
  EXPECT_LT(largest_difference(700, 64, 8, 16, 200, 64), 2e-3f);
  set_threads(saved);
}

TEST_F(OneHotTailTest, ATailThatIsNotOneHotIsMultipliedNotGathered) {
  // 18 tail columns: two blocks of eight for the vector scan and two for its scalar end. A
  // probability in either part must make the product dense (a gather would read it as 0).
  Parameter& w = input("w", {20, 3});
  for (int bad_column : {5, 12, 19}) {
    Parameter& x = input("x" + std::to_string(bad_column), {4, 20});
    std::span<float> xv = x.value();
    std::fill(xv.begin(), xv.end(), 0.0f);
    for (int i = 0; i < 4; ++i) {
      xv[i * 20] = 0.25f * static_cast<float>(i + 1);  // dense columns 0-1
      xv[i * 20 + 2 + i] = 1.0f;
    }
    xv[20 + bad_column] = 0.5f;  // row 1
    const Tensor expect = linear(x.tensor(), w.tensor());
    for (bool vectorised : {true, false}) {
      set_one_hot_scan_vectorised(vectorised);
      const Tensor got = linear_one_hot_tail(x.tensor(), w.tensor(), Tensor(), 2);
      for (int i = 0; i < 12; ++i)
        EXPECT_NEAR(got.data()[i], expect.data()[i], 1e-6f) << bad_column << " " << i;
    }
    set_one_hot_scan_vectorised(true);
  }
}

TEST_F(OneHotTailTest, GradientsMatchFiniteDifferencesOfTheWeights) {
  Parameter& w = input("w", {10, 4});
  Parameter& b = input("b", {4});
  const std::vector<float> x = {0.3f,  -0.7f, 0, 1, 0, 0, 0, 1, 0, 0,  //
                                1.2f,  0.1f,  1, 0, 0, 0, 0, 0, 0, 1,  //
                                -0.4f, 0.9f,  0, 0, 1, 0, 0, 0, 0, 0};
  EXPECT_EQ(check("linear_one_hot_tail",
                  [&] {
                    return linear_one_hot_tail(constant({3, 10}, x), w.tensor(), b.tensor(), 2);
                  }),
            0);
}

}  // namespace
}  // namespace indrive::nn
