// Drawing a town: the PNG has the expected size and shows every route in its colour.
#include <gtest/gtest.h>

#include <opencv2/imgcodecs.hpp>

#include "net_test_town.h"
#include "testing.h"

namespace indrive::env {
namespace {

TEST(NetDrawTest, WritesTheTownWithItsRoutes) {
  const Town& town = testing::cached_town("town02");
  indrive::testing::TempDir dir;
  const auto path = dir.path() / "sub" / "town02.png";
  draw_town(town.net, town.routes, town.spawns, path, 2.0);
  const cv::Mat image = cv::imread(path.string(), cv::IMREAD_COLOR);
  ASSERT_FALSE(image.empty());
  // 207 m of network plus 12 m margins wide.
  const double width_m = town.net.max_corner().x() - town.net.min_corner().x() + 24.0;
  EXPECT_NEAR(image.cols, 2.0 * width_m, 2.0);
  EXPECT_GT(image.rows, image.cols);  // the legend sits below the map
  // Each route colour (BGR) covers many pixels.
  const cv::Vec3b colours[] = {{255, 170, 0}, {0, 140, 255}, {60, 220, 60}, {220, 60, 220}};
  for (const auto& colour : colours) {
    int count = 0;
    for (int y = 0; y < image.rows; ++y) {
      for (int x = 0; x < image.cols; ++x) count += image.at<cv::Vec3b>(y, x) == colour;
    }
    EXPECT_GT(count, 200) << colour;
  }
}

TEST(NetDrawTest, UnwritablePathIsAMapError) {
  const Town& town = testing::cached_town("town02");
  EXPECT_THROW(draw_town(town.net, town.routes, town.spawns, "/proc/no/such/dir/town.png"),
               MapError);
}

}  // namespace
}  // namespace indrive::env
