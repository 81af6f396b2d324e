// The fixture every ops test uses: inputs are parameters so that the gradient check sees them;
// values against direct formulas, gradients against central finite differences (grad_check.h).
#pragma once

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <functional>
#include <string>
#include <vector>

#include "grad_check.h"
#include "indrive/nn/kernels.h"
#include "indrive/nn/nn.h"

namespace indrive::nn::testing {

// Test inputs are parameters so that the gradient check sees them.
class OpsTest : public ::testing::Test {
 protected:
  void SetUp() override { current_graph().reset(); }
  Parameter& input(const std::string& name, const Shape& shape, float lo = -1.0f, float hi = 1.0f) {
    Parameter& p = in_.add(name, shape);
    fill_uniform(p, rng_, lo, hi);
    return p;
  }
  // Moves every value of p at least `gap` away from `kink` (keeps finite differences smooth).
  static void avoid(Parameter& p, float kink, float gap = 0.05f) {
    for (float& v : p.value())
      if (std::fabs(v - kink) < gap) v = kink + (v < kink ? -gap : gap);
  }
  int check(const std::string& what, const std::function<Tensor()>& f, GradTolerance tol = {}) {
    return check_gradients(what, f, {&in_}, tol);
  }
  ParamGroup in_{"in"};
  Rng rng_{1234};
};

}  // namespace indrive::nn::testing

namespace indrive::nn {
using testing::check_gradients;
using testing::fill_uniform;
using testing::GradTolerance;
using testing::OpsTest;
}  // namespace indrive::nn
