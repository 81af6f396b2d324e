// Tests of the bird's-eye view: placement and orientation, classes, the ego marker, overlays.
#include "indrive/envserver/bev.h"

#include <gtest/gtest.h>

#include "camera_scenes.h"

namespace indrive::env {
namespace {

constexpr double kPi = 3.14159265358979323846;

std::uint8_t id(SemanticClass cls) { return static_cast<std::uint8_t>(cls); }

TEST(BirdsEyeViewTest, EgoPointsUpAndPixelsMapToWorldPoints) {
  BirdsEyeView bev(BevConfig{.size_px = 256, .extent_m = 40.0, .ego_row_fraction = 0.5},
                   testing::straight_road());
  // 256 px over 40 m: 6.4 px per metre; ego at (128, 128).
  const Pose2 east{10.0, -1.75, 0.0};
  Eigen::Vector2d p = bev.to_pixel(east, {20.0, -1.75});  // 10 m ahead
  EXPECT_NEAR(p.x(), 128.0, 1e-9);
  EXPECT_NEAR(p.y(), 128.0 - 64.0, 1e-9);
  p = bev.to_pixel(east, {10.0, 3.25});  // 5 m to the left
  EXPECT_NEAR(p.x(), 128.0 - 32.0, 1e-9);
  EXPECT_NEAR(p.y(), 128.0, 1e-9);
  // Heading north: a point north is still up, a point east is to the right.
  const Pose2 north{0.0, 0.0, kPi / 2};
  p = bev.to_pixel(north, {0.0, 10.0});
  EXPECT_NEAR(p.x(), 128.0, 1e-9);
  EXPECT_NEAR(p.y(), 64.0, 1e-9);
  p = bev.to_pixel(north, {5.0, 0.0});
  EXPECT_NEAR(p.x(), 160.0, 1e-9);
}

TEST(BirdsEyeViewTest, ClassesShowRoadAlongTheHeadingAndVehicles) {
  BirdsEyeView bev(BevConfig{.size_px = 200, .extent_m = 40.0, .ego_row_fraction = 0.5},
                   testing::straight_road());
  const Box ego = testing::car_at(10.0, -1.75);
  const Box other = testing::car_at(22.0, 1.75, kPi);
  cv::Mat ids;
  bev.render_classes(ego, std::span<const Box>(&other, 1), ids);
  ASSERT_EQ(ids.type(), CV_8UC1);
  ASSERT_EQ(ids.rows, 200);
  // 5 px per metre; ego at (100, 100).
  EXPECT_EQ(ids.at<std::uint8_t>(100, 100), id(SemanticClass::kVehicle));  // ego
  EXPECT_EQ(ids.at<std::uint8_t>(40, 100), id(SemanticClass::kRoad));      // 12 m ahead, own lane
  EXPECT_EQ(ids.at<std::uint8_t>(40, 100 - 17), id(SemanticClass::kVehicle));  // other car
  // The centre line 1.75 m to the left: column 100 - 8.75 = 91.25 (pixel 91).
  EXPECT_EQ(ids.at<std::uint8_t>(150, 91), id(SemanticClass::kRoadLine));
  // Sidewalk 4.5 m to the right (column 122), vegetation 10 m to the right.
  EXPECT_EQ(ids.at<std::uint8_t>(150, 100 + 13), id(SemanticClass::kSidewalk));
  EXPECT_EQ(ids.at<std::uint8_t>(150, 100 + 50), id(SemanticClass::kVegetation));
  // Turned 90 degrees left, the road runs across the image.
  Box turned = ego;
  turned.pose.yaw_rad = kPi / 2;
  bev.render_classes(turned, {}, ids);
  // 1 m north (y = -0.75) and 16 m west of the ego: road; 1.8 m north: the centre line.
  EXPECT_EQ(ids.at<std::uint8_t>(100 - 5, 20), id(SemanticClass::kRoad));
  EXPECT_EQ(ids.at<std::uint8_t>(100 - 9, 20), id(SemanticClass::kRoadLine));
  EXPECT_EQ(ids.at<std::uint8_t>(100 - 50, 100), id(SemanticClass::kVegetation));  // 10 m north
}

TEST(BirdsEyeViewTest, ColourImageDrawsEgoRouteAndAlert) {
  BirdsEyeView bev(BevConfig{.size_px = 200, .extent_m = 40.0, .ego_row_fraction = 0.5},
                   testing::straight_road());
  const Box ego = testing::car_at(10.0, -1.75);
  const std::vector<Eigen::Vector2d> route = {{10.0, -1.75}, {40.0, -1.75}};
  const cv::Mat rgb = bev.render(ego, {}, {.route = route});
  ASSERT_EQ(rgb.type(), CV_8UC3);
  // Rear half of the ego is white, outside the palette.
  EXPECT_EQ(rgb.at<cv::Vec3b>(108, 100), cv::Vec3b(255, 255, 255));
  // The route runs up from the ego: yellow pixels 10 m ahead.
  const cv::Vec3b route_pixel = rgb.at<cv::Vec3b>(50, 100);
  EXPECT_GT(route_pixel[0], 200);
  EXPECT_GT(route_pixel[1], 180);
  EXPECT_LT(route_pixel[2], 80);
  const cv::Mat alert = bev.render(ego, {}, {.alert = true});
  EXPECT_EQ(alert.at<cv::Vec3b>(108, 100), cv::Vec3b(255, 0, 0));
  // No route: plain road there.
  EXPECT_EQ(alert.at<cv::Vec3b>(50, 100), cv::Vec3b(128, 64, 128));
}

TEST(BirdsEyeViewTest, BadConfigThrows) {
  const StaticScene scene = testing::straight_road();
  EXPECT_THROW(BirdsEyeView(BevConfig{.size_px = 0}, scene), CameraError);
  EXPECT_THROW(BirdsEyeView(BevConfig{.extent_m = -1.0}, scene), CameraError);
  EXPECT_THROW(BirdsEyeView(BevConfig{.ego_row_fraction = 2.0}, scene), CameraError);
}

}  // namespace
}  // namespace indrive::env
