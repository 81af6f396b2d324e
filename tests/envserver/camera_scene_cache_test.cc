// Tests of the static scene cache: ground rasterisation order, painted and dashed lines, the
// line pyramid's footprint rule, the box index, and bad scenes.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "camera_scenes.h"
#include "indrive/envserver/camera.h"

namespace indrive::env {
namespace {

StaticScene empty_scene() {
  StaticScene scene;
  scene.ground_class = SemanticClass::kVegetation;
  scene.min_corner = {-50, -50};
  scene.max_corner = {50, 50};
  return scene;
}

TEST(SceneCacheTest, LaterGroundPolygonsCoverEarlierOnes) {
  StaticScene scene = empty_scene();
  scene.ground.push_back({SemanticClass::kRoad, {{-10, -10}, {10, -10}, {10, 10}, {-10, 10}}});
  scene.ground.push_back({SemanticClass::kSidewalk, {{0, 0}, {20, 0}, {20, 20}, {0, 20}}});
  const SceneCache cache(scene);
  EXPECT_EQ(cache.ground_at(-5, -5), SemanticClass::kRoad);
  EXPECT_EQ(cache.ground_at(5, 5), SemanticClass::kSidewalk);
  EXPECT_EQ(cache.ground_at(15, 15), SemanticClass::kSidewalk);
  EXPECT_EQ(cache.ground_at(-15, 0), SemanticClass::kVegetation);  // nothing there
  EXPECT_EQ(cache.ground_at(1e4, 0), SemanticClass::kVegetation);  // outside the map
  // Edges land within one cell of where they are.
  EXPECT_EQ(cache.ground_at(9.85, -5), SemanticClass::kRoad);
  EXPECT_EQ(cache.ground_at(10.15, -5), SemanticClass::kVegetation);
  // A clockwise polygon fills the same.
  StaticScene clockwise = empty_scene();
  clockwise.ground.push_back({SemanticClass::kRoad, {{-10, 10}, {10, 10}, {10, -10}, {-10, -10}}});
  EXPECT_EQ(
      cv::countNonZero(SceneCache(clockwise).ground_map() != SceneCache([&] {
                                                               StaticScene s = empty_scene();
                                                               s.ground.push_back(scene.ground[0]);
                                                               return s;
                                                             }())
                                                                 .ground_map()),
      0);
}

TEST(SceneCacheTest, SolidLinesArePaintedAtTheirWidth) {
  StaticScene scene = empty_scene();
  scene.ground.push_back({SemanticClass::kRoad, {{-40, -5}, {40, -5}, {40, 5}, {-40, 5}}});
  scene.lines.push_back({{{-30, 0}, {0, 0}, {20, 20}}, 0.3, false});
  const SceneCache cache(scene);
  EXPECT_EQ(cache.ground_at(-10, 0.05), SemanticClass::kRoadLine);
  EXPECT_EQ(cache.ground_at(-10, -0.1), SemanticClass::kRoadLine);
  EXPECT_EQ(cache.ground_at(-10, 0.35), SemanticClass::kRoad);
  EXPECT_EQ(cache.ground_at(-31, 0), SemanticClass::kRoad);  // past the end
  // The bend and the diagonal part.
  EXPECT_EQ(cache.ground_at(0.0, 0.0), SemanticClass::kRoadLine);
  EXPECT_EQ(cache.ground_at(3.0, 3.0), SemanticClass::kRoadLine);
  EXPECT_EQ(cache.ground_at(3.0, 2.0), SemanticClass::kRoad);
}

TEST(SceneCacheTest, DashedLinesFollowArcLengthAcrossVertices) {
  StaticScene scene = empty_scene();
  // 3 m painted, 6 m gap, measured along the polyline: the corner at (5, 0) is s = 5.
  scene.lines.push_back({{{0, 0}, {5, 0}, {5, 20}}, 0.2, true});
  const SceneCache cache(scene);
  EXPECT_EQ(cache.ground_at(1.5, 0), SemanticClass::kRoadLine);    // s = 1.5
  EXPECT_EQ(cache.ground_at(4.0, 0), SemanticClass::kVegetation);  // s = 4, gap
  EXPECT_EQ(cache.ground_at(5, 2.0), SemanticClass::kVegetation);  // s = 7, gap
  EXPECT_EQ(cache.ground_at(5, 5.5), SemanticClass::kRoadLine);    // s = 10.5, second dash
  EXPECT_EQ(cache.ground_at(5, 8.5), SemanticClass::kVegetation);  // s = 13.5
  EXPECT_EQ(cache.ground_at(5, 14.5), SemanticClass::kRoadLine);   // s = 19.5, third dash
}

TEST(SceneCacheTest, LineWinsWhereItCrossesAWideFootprint) {
  StaticScene scene = empty_scene();
  scene.ground.push_back({SemanticClass::kRoad, {{-40, -5}, {40, -5}, {40, 5}, {-40, 5}}});
  scene.lines.push_back({{{-40, 0}, {40, 0}}, 0.15, false});
  const SceneCache cache(scene);
  EXPECT_EQ(cache.line_level_for(0.05), 0);
  EXPECT_EQ(cache.line_level_for(0.1), 0);
  EXPECT_EQ(cache.line_level_for(0.15), 1);
  EXPECT_EQ(cache.line_level_for(0.2), 1);
  EXPECT_EQ(cache.line_level_for(0.25), 2);
  EXPECT_EQ(cache.line_level_for(1e6), cache.num_levels() - 1);
  // 0.5 m beside the line: road for a sharp pixel, line for a pixel 1.6 m wide.
  EXPECT_EQ(cache.ground_seen(3.0, 0.5, 0.05), SemanticClass::kRoad);
  EXPECT_EQ(cache.ground_seen(3.0, 0.5, 1.6), SemanticClass::kRoadLine);
  // Far from the line even a wide pixel sees road.
  EXPECT_EQ(cache.ground_seen(3.0, 3.5, 1.6), SemanticClass::kRoad);
  // Each level is the OR of the one below.
  for (int level = 1; level < cache.num_levels(); ++level) {
    const cv::Mat& fine = level == 1 ? cache.ground_map() : cache.line_level(level - 1);
    const cv::Mat& coarse = cache.line_level(level);
    EXPECT_EQ(coarse.rows, (fine.rows + 1) / 2);
    EXPECT_EQ(coarse.cols, (fine.cols + 1) / 2);
    const int fine_lines = level == 1 ? cv::countNonZero(fine == 2) : cv::countNonZero(fine);
    EXPECT_GT(cv::countNonZero(coarse), 0);
    EXPECT_LE(cv::countNonZero(coarse), fine_lines);
  }
}

TEST(SceneCacheTest, BoxIndexReturnsOverlappingBoxesOnce) {
  StaticScene scene = empty_scene();
  scene.boxes.push_back({SemanticClass::kBuilding, {0, 0, 0}, 10, 10, 5});
  scene.boxes.push_back({SemanticClass::kBuilding, {200, 0, 0}, 10, 10, 5});
  scene.boxes.push_back({SemanticClass::kVegetation, {100, 100, 0.7}, 150, 4, 5});  // spans cells
  const SceneCache cache(scene, SceneCacheOptions{.box_grid_cell_m = 16.0});
  std::vector<int> found;
  cache.boxes_in({-20, -20}, {20, 20}, found);
  EXPECT_EQ(found, (std::vector<int>{0}));
  found.clear();
  cache.boxes_in({-1000, -1000}, {1000, 1000}, found);
  EXPECT_EQ(found, (std::vector<int>{0, 1, 2}));
  found.clear();
  cache.boxes_in({5000, 5000}, {6000, 6000}, found);
  EXPECT_TRUE(found.empty());
}

TEST(SceneCacheTest, NonFiniteSceneThrowsClearError) {
  StaticScene scene = empty_scene();
  scene.ground.push_back(
      {SemanticClass::kRoad, {{0, 0}, {std::numeric_limits<double>::quiet_NaN(), 1}, {1, 1}}});
  try {
    SceneCache cache(scene);
    FAIL() << "expected CameraError";
  } catch (const CameraError& error) {
    EXPECT_NE(std::string(error.what()).find("non-finite"), std::string::npos) << error.what();
  }
}

TEST(SceneCacheTest, HugeSceneIsCoarsenedOrRejected) {
  StaticScene scene = empty_scene();
  scene.min_corner = {0, 0};
  scene.max_corner = {2000, 2000};
  const SceneCache coarse(scene, SceneCacheOptions{.max_cells = 10'000'000});
  EXPECT_GT(coarse.resolution_m(), 0.1);
  EXPECT_LE(static_cast<double>(coarse.ground_map().total()), 10'000'000.0);
  EXPECT_THROW(SceneCache(scene, SceneCacheOptions{.max_cells = 1000}), CameraError);
  EXPECT_THROW(SceneCache(scene, SceneCacheOptions{.resolution_m = 0.0}), CameraError);
}

TEST(SceneCacheTest, EmptySceneIsAllGroundClass) {
  StaticScene scene;
  scene.ground_class = SemanticClass::kUnlabeled;
  const SceneCache cache(scene);
  EXPECT_EQ(cache.ground_at(0, 0), SemanticClass::kUnlabeled);
  std::vector<int> found;
  cache.boxes_in({-10, -10}, {10, 10}, found);
  EXPECT_TRUE(found.empty());
}

}  // namespace
}  // namespace indrive::env
