// Central finite-difference gradient checks for the nn engine's tests.
//
// The values to check are parameters (test inputs are made parameters too, so their gradients
// accumulate in one place). The output of `forward` is reduced with fixed random weights R to
// L = sum(out * R), so every output element contributes; L is evaluated in double on the host
// for the finite differences, and backpropagated by the engine for the analytic gradient.
#pragma once

#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <string>
#include <vector>

#include "indrive/nn/nn.h"

namespace indrive::nn::testing {

struct GradTolerance {
  float step = 5e-3f;  // finite-difference step h
  float atol = 2e-3f;  // |analytic - numeric| <= atol + rtol * max(|analytic|, |numeric|)
  float rtol = 2e-2f;
};

// Fills a parameter with uniform values in [lo, hi).
inline void fill_uniform(Parameter& p, Rng& rng, float lo = -1.0f, float hi = 1.0f) {
  for (float& v : p.value()) v = lo + (hi - lo) * rng.uniform();
}

// Checks d(sum(forward() * R))/d(every value of every parameter in `groups`). Returns the
// number of mismatches (each is also reported as a test failure with its location).
inline int check_gradients(const std::string& what, const std::function<Tensor()>& forward,
                           std::vector<ParamGroup*> groups, GradTolerance tol = {},
                           std::uint64_t seed = 99) {
  Graph& graph = current_graph();
  // Analytic gradients.
  graph.reset();
  for (ParamGroup* g : groups) g->zero_grad();
  Tensor out = forward();
  std::vector<float> weights(static_cast<std::size_t>(out.numel()));
  Rng rng(seed);
  for (float& w : weights) w = 2.0f * rng.uniform() - 1.0f;
  Tensor loss = sum(mul(out, constant(out.shape(), weights)));
  graph.backward(loss);
  std::vector<std::vector<float>> analytic;
  for (ParamGroup* g : groups)
    for (const auto& p : g->params()) analytic.emplace_back(p->grad().begin(), p->grad().end());

  auto evaluate = [&]() {
    graph.reset();
    Tensor y;
    {
      NoGradGuard no_grad;
      y = forward();
    }
    double total = 0.0;
    for (std::int64_t i = 0; i < y.numel(); ++i)
      total += static_cast<double>(y.data()[i]) * weights[static_cast<std::size_t>(i)];
    return total;
  };

  int mismatches = 0;
  std::size_t index = 0;
  for (ParamGroup* g : groups)
    for (const auto& p : g->params()) {
      const std::vector<float>& a = analytic[index++];
      for (std::int64_t i = 0; i < p->numel(); ++i) {
        float& v = p->value()[static_cast<std::size_t>(i)];
        const float orig = v;
        v = orig + tol.step;
        const double up = evaluate();
        v = orig - tol.step;
        const double down = evaluate();
        v = orig;
        const double numeric = (up - down) / (2.0 * tol.step);
        const double ana = a[static_cast<std::size_t>(i)];
        const double bound = tol.atol + tol.rtol * std::max(std::fabs(numeric), std::fabs(ana));
        if (std::fabs(numeric - ana) > bound) {
          if (++mismatches <= 5)
            ADD_FAILURE() << what << ": d/d " << p->name() << "[" << i << "] analytic " << ana
                          << " numeric " << numeric;
        }
      }
    }
  graph.reset();
  return mismatches;
}

}  // namespace indrive::nn::testing
