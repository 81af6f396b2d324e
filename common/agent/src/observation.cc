#include "indrive/agent/observation.h"

#include "indrive/basics/check.h"

namespace indrive::agent {

void class_ids_to_rgb(std::span<const std::uint8_t> ids, std::span<float> rgb) {
  INDRIVE_CHECK_EQ(rgb.size(), 3 * ids.size());
  // A lookup table of floats avoids a divide per channel.
  static const std::array<std::array<float, 3>, kNumClasses> table = [] {
    std::array<std::array<float, 3>, kNumClasses> t{};
    for (int c = 0; c < kNumClasses; ++c) {
      for (int k = 0; k < 3; ++k) t[c][k] = kPaletteRgb[c][k] / 255.0f;
    }
    return t;
  }();
  for (std::size_t i = 0; i < ids.size(); ++i) {
    INDRIVE_CHECK_LT(static_cast<int>(ids[i]), kNumClasses) << "class id out of range";
    const auto& c = table[ids[i]];
    rgb[3 * i] = c[0], rgb[3 * i + 1] = c[1], rgb[3 * i + 2] = c[2];
  }
}

}  // namespace indrive::agent
