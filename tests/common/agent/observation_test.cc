#include "indrive/agent/observation.h"

#include <gtest/gtest.h>

#include <vector>

namespace indrive::agent {
namespace {

TEST(Observation, ClassIdsBecomeScaledRgb) {
  const std::vector<std::uint8_t> ids = {1, 0, 7};
  std::vector<float> rgb(9);
  class_ids_to_rgb(ids, rgb);
  EXPECT_FLOAT_EQ(rgb[0], 128 / 255.0f);  // road
  EXPECT_FLOAT_EQ(rgb[1], 64 / 255.0f);
  EXPECT_FLOAT_EQ(rgb[2], 128 / 255.0f);
  EXPECT_FLOAT_EQ(rgb[3], 0.0f);          // unlabeled
  EXPECT_FLOAT_EQ(rgb[8], 180 / 255.0f);  // sky blue
}

}  // namespace
}  // namespace indrive::agent
