// Tests of the semantic camera: hand-computed pixels on a known scene, motion of lines and
// vehicles, near-plane clipping and occlusion against a brute-force ray caster, determinism.
#include "indrive/envserver/camera.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <opencv2/imgproc.hpp>
#include <random>

#include "camera_scenes.h"

namespace indrive::env {
namespace {

using testing::car_at;
using testing::straight_road;

constexpr double kPi = 3.14159265358979323846;

std::uint8_t id(SemanticClass cls) { return static_cast<std::uint8_t>(cls); }

int count(const cv::Mat& ids, SemanticClass cls) { return cv::countNonZero(ids == id(cls)); }

// Columns of one row that hold the given class.
std::vector<int> columns_of(const cv::Mat& ids, int row, SemanticClass cls) {
  std::vector<int> cols;
  for (int col = 0; col < ids.cols; ++col)
    if (ids.at<std::uint8_t>(row, col) == id(cls)) cols.push_back(col);
  return cols;
}

// Reference renderer: one ray per pixel centre, exact box intersection (slab test in the box
// frame), nearest hit with camera depth >= near wins; otherwise the ground point the ray meets,
// looked up in the scene cache with the same footprint rule the camera documents.
cv::Mat ray_cast(const CameraConfig& config, const SceneCache& cache, const Pose2& ego,
                 const std::vector<Box>& boxes) {
  cv::Mat ids(config.height, config.width, CV_8UC1);
  const double f = 0.5 * config.width / std::tan(0.5 * config.hfov_deg * kPi / 180.0);
  const double p = config.pitch_deg * kPi / 180.0;
  const double cy = std::cos(ego.yaw_rad), sy = std::sin(ego.yaw_rad);
  // Camera origin and axes in the world frame.
  const Eigen::Vector3d origin(ego.x_m + cy * config.forward_m, ego.y_m + sy * config.forward_m,
                               config.height_m);
  const Eigen::Vector3d forward(cy, sy, 0.0), left(-sy, cy, 0.0), up(0, 0, 1);
  const Eigen::Vector3d axis_z = std::cos(p) * forward - std::sin(p) * up;
  const Eigen::Vector3d axis_x = -left;
  const Eigen::Vector3d axis_y = -std::sin(p) * forward - std::cos(p) * up;
  for (int row = 0; row < config.height; ++row)
    for (int col = 0; col < config.width; ++col) {
      const double a = (col + 0.5 - 0.5 * config.width) / f;
      const double b = (row + 0.5 - 0.5 * config.height) / f;
      // t along this direction is the camera depth.
      const Eigen::Vector3d dir = a * axis_x + b * axis_y + axis_z;
      double best = std::numeric_limits<double>::infinity();
      SemanticClass cls = SemanticClass::kSky;
      for (const Box& box : boxes) {
        const double c = std::cos(box.pose.yaw_rad), s = std::sin(box.pose.yaw_rad);
        // The camera's documented rule: a box wholly beyond the far plane is not drawn.
        bool beyond_far = true;
        for (const double along : {-0.5, 0.5})
          for (const double across : {-0.5, 0.5})
            for (const double up_m : {0.0, box.height_m}) {
              const Eigen::Vector3d corner(
                  box.pose.x_m + c * along * box.length_m - s * across * box.width_m,
                  box.pose.y_m + s * along * box.length_m + c * across * box.width_m, up_m);
              beyond_far &= (corner - origin).dot(axis_z) > config.far_m;
            }
        if (beyond_far) continue;
        const Eigen::Vector3d o(origin.x() - box.pose.x_m, origin.y() - box.pose.y_m, origin.z());
        const Eigen::Vector3d lo(-0.5 * box.length_m, -0.5 * box.width_m, 0.0);
        const Eigen::Vector3d hi(0.5 * box.length_m, 0.5 * box.width_m, box.height_m);
        const Eigen::Vector3d ol(c * o.x() + s * o.y(), -s * o.x() + c * o.y(), o.z());
        const Eigen::Vector3d dl(c * dir.x() + s * dir.y(), -s * dir.x() + c * dir.y(), dir.z());
        double t0 = config.near_m, t1 = std::numeric_limits<double>::infinity();
        for (int k = 0; k < 3; ++k) {
          if (std::abs(dl[k]) < 1e-15) {
            if (ol[k] < lo[k] || ol[k] > hi[k]) t0 = t1 + 1;
            continue;
          }
          double ta = (lo[k] - ol[k]) / dl[k], tb = (hi[k] - ol[k]) / dl[k];
          if (ta > tb) std::swap(ta, tb);
          t0 = std::max(t0, ta);
          t1 = std::min(t1, tb);
        }
        if (t0 <= t1 && t0 < best) {
          best = t0;
          cls = box.cls;
        }
      }
      if (cls == SemanticClass::kSky && dir.z() < 0.0) {
        const double t = -origin.z() / dir.z();
        if (t > config.far_m) {
          cls = cache.ground_class();
        } else {
          const Eigen::Vector3d g = origin + t * dir;
          cls = cache.ground_seen(g.x(), g.y(), t / f);
        }
      }
      ids.at<std::uint8_t>(row, col) = id(cls);
    }
  return ids;
}

// Fraction of pixels that differ, ignoring pixels on a class boundary of the reference (where
// the exact edge falls within rounding of a pixel centre).
double interior_mismatch(const cv::Mat& got, const cv::Mat& want) {
  int differ = 0, total = 0;
  for (int r = 1; r + 1 < want.rows; ++r)
    for (int c = 1; c + 1 < want.cols; ++c) {
      const std::uint8_t w = want.at<std::uint8_t>(r, c);
      bool edge = false;
      for (int dr = -1; dr <= 1; ++dr)
        for (int dc = -1; dc <= 1; ++dc) edge |= want.at<std::uint8_t>(r + dr, c + dc) != w;
      if (edge) continue;
      ++total;
      differ += got.at<std::uint8_t>(r, c) != w;
    }
  return total == 0 ? 0.0 : static_cast<double>(differ) / total;
}

TEST(SemanticCameraTest, SkyAboveHorizonRoadAheadAndHandComputedGroundPixels) {
  SemanticCamera camera(CameraConfig{}, straight_road());
  const cv::Mat ids = camera.render(Pose2{0.0, -1.75, 0.0}, {});
  ASSERT_EQ(ids.type(), CV_8UC1);
  ASSERT_EQ(ids.rows, 128);
  ASSERT_EQ(ids.cols, 128);
  // Level camera, f = 64 px: rows above the centre (v < 64) look up.
  for (int row = 0; row < 64; ++row)
    EXPECT_EQ(columns_of(ids, row, SemanticClass::kSky).size(), 128u);
  // Row 100 (centre v = 100.5) meets the ground at depth 64 * 2.4 / 36.5 = 4.208 m. The lane
  // centre straight ahead (column 63/64) is road.
  EXPECT_EQ(ids.at<std::uint8_t>(100, 63), id(SemanticClass::kRoad));
  EXPECT_EQ(ids.at<std::uint8_t>(100, 64), id(SemanticClass::kRoad));
  // The centre line 1.75 m to the left spans u = 64 - 64 * (1.75 +- 0.075) / 4.208, i.e.
  // [36.24, 38.52]: pixel centres 36.5, 37.5 and 38.5 lie inside.
  EXPECT_EQ(columns_of(ids, 100, SemanticClass::kRoadLine), (std::vector<int>{36, 37, 38}));
  // The right road edge (y = -3.5, 1.75 m to the right) is at u = 64 + 26.6 = 90.6; beyond it
  // the sidewalk (2 m wide, to u = 121) and then vegetation.
  EXPECT_EQ(ids.at<std::uint8_t>(100, 89), id(SemanticClass::kRoad));
  EXPECT_EQ(ids.at<std::uint8_t>(100, 92), id(SemanticClass::kSidewalk));
  EXPECT_EQ(ids.at<std::uint8_t>(100, 124), id(SemanticClass::kVegetation));
  // Left of the centre line: the other lane, road again.
  EXPECT_EQ(ids.at<std::uint8_t>(100, 20), id(SemanticClass::kRoad));
}

TEST(SemanticCameraTest, ProjectMatchesPinholeModel) {
  SemanticCamera camera(CameraConfig{}, straight_road());
  // 10 m ahead of the camera, 2.4 m below it and 1 m to its left.
  const auto p = camera.project(Pose2{5.0, 2.0, 0.0}, Eigen::Vector3d(16.5, 3.0, 0.0));
  ASSERT_TRUE(p.has_value());
  EXPECT_NEAR(p->x(), 64.0 - 64.0 * 1.0 / 10.0, 1e-9);
  EXPECT_NEAR(p->y(), 64.0 + 64.0 * 2.4 / 10.0, 1e-9);
  // Rotated ego: the same relative point after turning everything by 90 degrees.
  const auto q = camera.project(Pose2{0.0, 0.0, kPi / 2}, Eigen::Vector3d(-1.0, 11.5, 0.0));
  ASSERT_TRUE(q.has_value());
  EXPECT_NEAR(q->x(), 64.0 - 6.4, 1e-9);
  EXPECT_NEAR(q->y(), 64.0 + 15.36, 1e-9);
  EXPECT_FALSE(camera.project(Pose2{}, Eigen::Vector3d(-3.0, 0.0, 1.0)).has_value());
}

TEST(SemanticCameraTest, LaneLineMovesLeftWhenEgoShiftsRight) {
  SemanticCamera camera(CameraConfig{}, straight_road());
  auto line_centre = [&](double ego_y) {
    const cv::Mat ids = camera.render(Pose2{0.0, ego_y, 0.0}, {});
    const std::vector<int> cols = columns_of(ids, 100, SemanticClass::kRoadLine);
    EXPECT_FALSE(cols.empty()) << "no line at ego y " << ego_y;
    double sum = 0.0;
    for (const int c : cols) sum += c + 0.5;
    return cols.empty() ? 0.0 : sum / cols.size();
  };
  // Expected u = 64 - 64 * (line offset to the left) / 4.208 m.
  const double at_lane_centre = line_centre(-1.75);
  const double shifted_right = line_centre(-2.75);
  const double shifted_left = line_centre(-0.75);
  EXPECT_NEAR(at_lane_centre, 64.0 - 64.0 * 1.75 / 4.2082, 0.6);
  EXPECT_NEAR(shifted_right, 64.0 - 64.0 * 2.75 / 4.2082, 0.6);
  EXPECT_NEAR(shifted_left, 64.0 - 64.0 * 0.75 / 4.2082, 0.6);
  EXPECT_LT(shifted_right, at_lane_centre);
  EXPECT_GT(shifted_left, at_lane_centre);
}

TEST(SemanticCameraTest, ThinLaneLineStaysVisibleAtDistance) {
  // A 0.15 m line is under a pixel wide beyond ~10 m at 128 px and beyond ~2.5 m at 32 px;
  // the footprint rule must still show it in every ground row up to 60 m, near where it is.
  for (const int size : {128, 64, 32}) {
    SemanticCamera camera(CameraConfig{.width = size, .height = size}, straight_road());
    const cv::Mat ids = camera.render(Pose2{0.0, -1.75, 0.0}, {});
    const double f = 0.5 * size;
    for (int row = size / 2; row < size; ++row) {
      const double depth = f * 2.4 / (row + 0.5 - f);
      if (depth > 60.0 || depth < 2.0) continue;
      const double u = f - f * 1.75 / depth;
      const std::vector<int> cols = columns_of(ids, row, SemanticClass::kRoadLine);
      ASSERT_FALSE(cols.empty()) << size << " px, row " << row << " (depth " << depth << " m)";
      for (const int c : cols)
        EXPECT_LE(std::abs(c + 0.5 - u), 2.0 + 0.15 * f / depth)
            << size << " px, row " << row << " col " << c;
    }
  }
}

TEST(SemanticCameraTest, ThinLaneLineNeverDropsOutWhileDrivingAtAnyRoadAngle) {
  // The same straight road turned by several angles against the map grid (the pyramid cells
  // are axis-aligned, so diagonal roads are the hard case), driven in small steps with a
  // little weaving: the centre line must show in every ground row up to 60 m in every frame.
  for (const double angle_deg : {0.0, 17.0, 45.0, 63.0}) {
    const double a = angle_deg * kPi / 180.0;
    const Eigen::Vector2d along(std::cos(a), std::sin(a)), across(-std::sin(a), std::cos(a));
    StaticScene scene;
    scene.ground_class = SemanticClass::kVegetation;
    auto at = [&](double s, double t) -> Eigen::Vector2d { return s * along + t * across; };
    scene.ground.push_back(
        {SemanticClass::kRoad, {at(-20, -3.5), at(150, -3.5), at(150, 3.5), at(-20, 3.5)}});
    scene.lines.push_back({{at(-20, 0.0), at(150, 0.0)}, 0.15, false});
    auto cache = std::make_shared<const SceneCache>(scene);
    for (const int size : {128, 64, 32}) {
      SemanticCamera camera(CameraConfig{.width = size, .height = size}, cache);
      const double f = 0.5 * size;
      cv::Mat ids;
      for (int step = 0; step < 25; ++step) {
        const double lateral = -1.75 + 0.3 * std::sin(0.7 * step);
        const Eigen::Vector2d position = at(0.37 * step, lateral);
        camera.render(Pose2{position.x(), position.y(), a + 0.02 * std::cos(0.5 * step)}, {}, ids);
        for (int row = size / 2; row < size; ++row) {
          const double depth = f * 2.4 / (row + 0.5 - f);
          if (depth > 60.0 || depth < 2.5) continue;
          ASSERT_FALSE(columns_of(ids, row, SemanticClass::kRoadLine).empty())
              << "angle " << angle_deg << ", " << size << " px, step " << step << ", row " << row
              << " (depth " << depth << " m)";
        }
      }
    }
  }
}

TEST(SemanticCameraTest, VehicleAheadAppearsAndGrowsAsItApproaches) {
  SemanticCamera camera(CameraConfig{}, straight_road());
  const Pose2 ego{0.0, -1.75, 0.0};
  int previous = 0;
  for (const double distance : {100.0, 50.0, 25.0, 12.0, 6.0}) {
    const Box car = car_at(distance, -1.75);
    const cv::Mat ids = camera.render(ego, std::span<const Box>(&car, 1));
    const int pixels = count(ids, SemanticClass::kVehicle);
    EXPECT_GT(pixels, previous) << "at " << distance << " m";
    previous = pixels;
    // It sits straight ahead: its pixels straddle the centre column.
    cv::Mat mask = ids == id(SemanticClass::kVehicle);
    const cv::Rect bounds = cv::boundingRect(mask);
    EXPECT_LE(bounds.x, 64);
    EXPECT_GE(bounds.x + bounds.width, 64);
  }
  // The rear face of a car 6 m ahead of the ego (3.6 m from the camera): 2.1 m wide, so about
  // 64 * 2.1 / 2.1 = 64 columns; 1.5 m high seen from 2.4 m: rows 64 + 64 * 0.9 / 2.1 = 91.4
  // down to 64 + 64 * 2.4 / 2.1 = 137 (past the bottom), plus the roof above.
  const Box near_car = car_at(6.0, -1.75);
  const cv::Mat ids = camera.render(ego, std::span<const Box>(&near_car, 1));
  EXPECT_NEAR(static_cast<double>(columns_of(ids, 120, SemanticClass::kVehicle).size()), 64.0, 1.0);
  // Beyond the far plane (120 m) a vehicle is not drawn.
  const Box far_car = car_at(200.0, -1.75);
  EXPECT_EQ(count(camera.render(ego, std::span<const Box>(&far_car, 1)), SemanticClass::kVehicle),
            0);
}

TEST(SemanticCameraTest, BoxBehindCameraDrawsNothing) {
  SemanticCamera camera(CameraConfig{}, straight_road());
  const Pose2 ego{50.0, -1.75, 0.0};
  const cv::Mat empty = camera.render(ego, {});
  // Behind the ego, and a box just behind the camera plane (between ego centre and camera).
  const std::vector<Box> behind = {
      car_at(40.0, -1.75), car_at(44.0, 1.75),
      Box{SemanticClass::kBuilding, {50.0, -1.75, 0.0}, 2.0, 1.0, 10.0}};
  const cv::Mat ids = camera.render(ego, behind);
  EXPECT_EQ(cv::countNonZero(ids != empty), 0);
}

TEST(SemanticCameraTest, BoxCrossingNearPlaneIsClippedNotMirrored) {
  SemanticCamera camera(CameraConfig{}, straight_road());
  const Pose2 ego{0.0, -1.75, 0.0};
  // A car in the left lane whose rear half is behind the camera plane (x = 1.5): it spans
  // x in [1.1, 5.9], its near side 2.45 m left of the camera. Its front corner projects to
  // u = 64 - 64 * 2.45 / 4.4 = 28.4; everything else of it lies further left, off to u < 0.
  const Box beside = car_at(3.5, 1.75);
  const cv::Mat ids = camera.render(ego, std::span<const Box>(&beside, 1));
  const cv::Rect bounds = cv::boundingRect(ids == id(SemanticClass::kVehicle));
  ASSERT_GT(bounds.area(), 0) << "the front half of the car must be visible at the left edge";
  EXPECT_EQ(bounds.x, 0);
  // A mirrored projection of the part behind the camera would show up on the right.
  EXPECT_NEAR(bounds.x + bounds.width, 29, 1);
  // A wall along the left of the road from behind the ego to far ahead.
  const Box wall{SemanticClass::kBuilding, {5.0, 7.0, 0.0}, 50.0, 2.0, 12.0};
  const cv::Mat wall_ids = camera.render(ego, std::span<const Box>(&wall, 1));
  const cv::Rect wall_bounds = cv::boundingRect(wall_ids == id(SemanticClass::kBuilding));
  EXPECT_EQ(wall_bounds.x, 0);
  EXPECT_LT(wall_bounds.x + wall_bounds.width, 64);
  EXPECT_EQ(wall_ids.at<std::uint8_t>(0, 0), id(SemanticClass::kBuilding));
}

TEST(SemanticCameraTest, NearBoxHidesFarBoxWhateverTheDrawOrder) {
  SemanticCamera camera(CameraConfig{}, straight_road());
  const Pose2 ego{0.0, -1.75, 0.0};
  // The car's rear face is 11.1 m from the camera, rows 69.2 to 77.8 and its roof up to 67.6;
  // the building's face is 20.5 m away and reaches down to row 71.5, so the two overlap on
  // rows 68 to 71 over the car's columns.
  const Box near_car = car_at(15.0, -1.75);
  const Box far_building{SemanticClass::kBuilding, {25.0, -1.75, 0.0}, 6.0, 6.0, 8.0};
  const std::vector<Box> near_first = {near_car, far_building};
  const std::vector<Box> far_first = {far_building, near_car};
  const cv::Mat a = camera.render(ego, near_first);
  const cv::Mat b = camera.render(ego, far_first);
  EXPECT_EQ(cv::countNonZero(a != b), 0);
  auto class_at = [&](const cv::Mat& ids, const Eigen::Vector3d& world) {
    const auto p = camera.project(ego, world);
    EXPECT_TRUE(p.has_value());
    return ids.at<std::uint8_t>(static_cast<int>(p->y()), static_cast<int>(p->x()));
  };
  // Upper part of the car's rear face (row 70): the building is behind it there.
  EXPECT_EQ(class_at(a, {12.6, -1.75, 1.2}), id(SemanticClass::kVehicle));
  EXPECT_EQ(class_at(b, {12.6, -1.75, 1.2}), id(SemanticClass::kVehicle));
  // Above the car the building shows.
  EXPECT_EQ(class_at(a, {22.0, -1.75, 6.0}), id(SemanticClass::kBuilding));
  // Without the car the same pixel as the car's face shows the building.
  const cv::Mat alone = camera.render(ego, std::span<const Box>(&far_building, 1));
  EXPECT_EQ(class_at(alone, {12.6, -1.75, 1.2}), id(SemanticClass::kBuilding));
}

TEST(SemanticCameraTest, MatchesBruteForceRayCasterOnRandomScenes) {
  // Random boxes all around the ego, some crossing the camera plane, some overlapping in view:
  // the rasteriser must agree with an exact per-pixel ray caster away from class edges.
  const StaticScene road = straight_road();
  auto cache = std::make_shared<const SceneCache>(road);
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> along(-15.0, 60.0), across(-12.0, 12.0), yaw(-kPi, kPi);
  std::uniform_real_distribution<double> size(1.0, 8.0), height(0.5, 12.0);
  for (const double pitch : {0.0, 8.0}) {
    for (const int image : {128, 64}) {
      const CameraConfig config{.width = image, .height = image, .pitch_deg = pitch};
      SemanticCamera camera(config, cache);
      for (int trial = 0; trial < 6; ++trial) {
        const Pose2 ego{along(rng) * 0.2, across(rng) * 0.1, yaw(rng) * 0.1};
        std::vector<Box> boxes;
        for (int k = 0; k < 25; ++k) {
          const SemanticClass cls = k % 3 == 0 ? SemanticClass::kBuilding : SemanticClass::kVehicle;
          Box box{cls,
                  {ego.x_m + along(rng), ego.y_m + across(rng), yaw(rng)},
                  size(rng),
                  size(rng),
                  height(rng)};
          // Keep the camera outside every box (the ego cannot be inside another box).
          const double dx = ego.x_m + 1.5 * std::cos(ego.yaw_rad) - box.pose.x_m;
          const double dy = ego.y_m + 1.5 * std::sin(ego.yaw_rad) - box.pose.y_m;
          if (std::hypot(dx, dy) < 0.5 * std::hypot(box.length_m, box.width_m) + 0.3) continue;
          boxes.push_back(box);
        }
        const cv::Mat got = camera.render(ego, boxes);
        const cv::Mat want = ray_cast(config, *cache, ego, boxes);
        EXPECT_LT(interior_mismatch(got, want), 0.002)
            << "pitch " << pitch << " size " << image << " trial " << trial;
      }
    }
  }
}

TEST(SemanticCameraTest, MatchesBruteForceRayCasterInATownWithStaticBoxes) {
  // The static boxes come through the grid index and the frustum's bounding rectangle; any box
  // wrongly dropped there shows up as a mismatch against the ray caster, which sees them all.
  const StaticScene town = testing::grid_town(3, 3, 80.0, 9);
  auto cache = std::make_shared<const SceneCache>(town, SceneCacheOptions{.box_grid_cell_m = 16.0});
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> along(0.0, 240.0), yaw(-kPi, kPi);
  for (const double far : {60.0, 120.0}) {
    const CameraConfig config{.width = 96, .height = 96, .pitch_deg = 3.0, .far_m = far};
    SemanticCamera camera(config, cache);
    for (int trial = 0; trial < 8; ++trial) {
      // On a road of the grid (x = 80 or y = 80), facing any way.
      const double s = along(rng);
      const Pose2 ego =
          trial % 2 == 0 ? Pose2{s, 80.0 - 1.75, yaw(rng)} : Pose2{80.0 + 1.75, s, yaw(rng)};
      std::vector<Box> all = town.boxes;
      const cv::Mat got = camera.render(ego, {});
      const cv::Mat want = ray_cast(config, *cache, ego, all);
      EXPECT_LT(interior_mismatch(got, want), 0.002) << "far " << far << " trial " << trial;
      EXPECT_GT(cv::countNonZero(got == id(SemanticClass::kBuilding)) +
                    cv::countNonZero(got == id(SemanticClass::kVegetation)),
                0);
    }
  }
}

TEST(SemanticCameraTest, StaticBoxesOfTheSceneAreDrawnAndCulledOutsideTheView) {
  StaticScene scene = straight_road();
  scene.boxes.push_back(
      {SemanticClass::kBuilding, {30.0, 12.0, 0.0}, 10.0, 8.0, 15.0});  // ahead left
  scene.boxes.push_back({SemanticClass::kVegetation, {-30.0, 0.0, 0.0}, 5.0, 5.0, 5.0});  // behind
  SemanticCamera camera(CameraConfig{}, scene);
  const cv::Mat ids = camera.render(Pose2{0.0, -1.75, 0.0}, {});
  EXPECT_GT(count(ids, SemanticClass::kBuilding), 50);
  EXPECT_EQ(count(ids, SemanticClass::kVegetation) -
                count(camera.render(Pose2{0.0, -1.75, 0.0}, {}), SemanticClass::kVegetation),
            0);
  // Turn around: now the vegetation box is ahead and the building behind.
  const cv::Mat back = camera.render(Pose2{0.0, -1.75, kPi}, {});
  EXPECT_EQ(count(back, SemanticClass::kBuilding), 0);
  const auto bush = camera.project(Pose2{0.0, -1.75, kPi}, Eigen::Vector3d(-27.5, 0.0, 2.5));
  ASSERT_TRUE(bush.has_value());
  EXPECT_EQ(back.at<std::uint8_t>(static_cast<int>(bush->y()), static_cast<int>(bush->x())),
            id(SemanticClass::kVegetation));
}

TEST(SemanticCameraTest, DeterministicAcrossCallsAndInstances) {
  const StaticScene scene = testing::grid_town(2, 2, 80.0, 5);
  SemanticCamera first(CameraConfig{}, scene);
  SemanticCamera second(CameraConfig{}, scene);
  const std::vector<Box> cars = {car_at(20.0, -1.75), car_at(35.0, 1.75, kPi),
                                 car_at(80.0, 30.0, kPi / 2)};
  cv::Mat reused;
  for (int step = 0; step < 20; ++step) {
    const Pose2 ego{3.0 + step * 0.7, -1.75, 0.01 * step};
    first.render(ego, cars, reused);
    const cv::Mat again = first.render(ego, cars);
    const cv::Mat other = second.render(ego, cars);
    ASSERT_EQ(cv::countNonZero(reused != again), 0);
    ASSERT_EQ(cv::countNonZero(reused != other), 0);
  }
}

TEST(SemanticCameraTest, PitchMovesTheHorizonUp) {
  const StaticScene scene = straight_road();
  SemanticCamera level(CameraConfig{}, scene);
  SemanticCamera pitched(CameraConfig{.pitch_deg = 10.0}, scene);
  const Pose2 ego{0.0, -1.75, 0.0};
  // Horizon row: v = cy - f tan(pitch) = 64 - 64 tan(10 deg) = 52.7.
  const cv::Mat ids = pitched.render(ego, {});
  EXPECT_EQ(ids.at<std::uint8_t>(51, 64), id(SemanticClass::kSky));
  EXPECT_NE(ids.at<std::uint8_t>(54, 64), id(SemanticClass::kSky));
  EXPECT_EQ(level.render(ego, {}).at<std::uint8_t>(54, 64), id(SemanticClass::kSky));
}

TEST(SemanticCameraTest, BadConfigThrowsNamingTheField) {
  const StaticScene scene = straight_road();
  auto message_of = [&](const CameraConfig& config) {
    try {
      SemanticCamera camera(config, scene);
    } catch (const CameraError& error) {
      return std::string(error.what());
    }
    return std::string("no error");
  };
  EXPECT_NE(message_of(CameraConfig{.width = 0}).find("width"), std::string::npos);
  EXPECT_NE(message_of(CameraConfig{.hfov_deg = 180.0}).find("hfov_deg"), std::string::npos);
  EXPECT_NE(message_of(CameraConfig{.height_m = -1.0}).find("height_m"), std::string::npos);
  EXPECT_NE(message_of(CameraConfig{.near_m = 200.0}).find("near_m"), std::string::npos);
}

TEST(ColorizeTest, UsesTheCarlaPaletteInRgbOrder) {
  cv::Mat ids(1, kNumSemanticClasses + 1, CV_8UC1);
  for (int k = 0; k < kNumSemanticClasses; ++k)
    ids.at<std::uint8_t>(0, k) = static_cast<std::uint8_t>(k);
  ids.at<std::uint8_t>(0, kNumSemanticClasses) = 200;  // out of range -> unlabeled
  const cv::Mat rgb = colorize(ids);
  ASSERT_EQ(rgb.type(), CV_8UC3);
  for (int k = 0; k < kNumSemanticClasses; ++k)
    for (int ch = 0; ch < 3; ++ch) EXPECT_EQ(rgb.at<cv::Vec3b>(0, k)[ch], kPaletteRgb[k][ch]);
  EXPECT_EQ(rgb.at<cv::Vec3b>(0, kNumSemanticClasses), cv::Vec3b(0, 0, 0));
  // Spot checks against the list: road 128,64,128; vehicle 0,0,142; sky 70,130,180.
  EXPECT_EQ(rgb.at<cv::Vec3b>(0, 1), cv::Vec3b(128, 64, 128));
  EXPECT_EQ(rgb.at<cv::Vec3b>(0, 4), cv::Vec3b(0, 0, 142));
  EXPECT_EQ(rgb.at<cv::Vec3b>(0, 7), cv::Vec3b(70, 130, 180));
}

}  // namespace
}  // namespace indrive::env
