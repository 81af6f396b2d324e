// Row reductions the intrinsic modules share (private to the agent library).
#pragma once

#include <algorithm>
#include <vector>

#include "indrive/nn/nn.h"

namespace indrive::agent::intrinsic_math {

// Mean over rows of mask * per_row, divided by the number of valid rows. per_row is (N, 1).
inline nn::Tensor masked_mean(nn::Tensor per_row, nn::Tensor mask) {
  float valid = 0;
  for (float m : mask.values()) valid += m;
  return nn::scale(nn::sum(nn::mul(per_row, mask)), 1.0f / std::max(1.0f, valid));
}

// Row sums of a (N, C) tensor as (N, 1).
inline nn::Tensor row_sum(nn::Tensor x) {
  return nn::reshape(nn::sum(x, -1), nn::Shape{x.dim(0), 1});
}

inline std::vector<float> to_vector(nn::Tensor x) { return {x.values().begin(), x.values().end()}; }

}  // namespace indrive::agent::intrinsic_math
