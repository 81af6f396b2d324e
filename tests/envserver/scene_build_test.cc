// The static scene of a built-in town: roads where the lanes are, sidewalks beside them,
// buildings clear of both, lines where the markings belong; spawn points on lanes.
#include "indrive/envserver/scene_build.h"

#include <gtest/gtest.h>

#include <cmath>

#include "indrive/envserver/net_geometry.h"
#include "net_test_town.h"

namespace indrive::env {
namespace {

// The class of the last-drawn ground polygon containing the point, as the camera would see it.
SemanticClass ground_class_at(const StaticScene& scene, const Eigen::Vector2d& point) {
  for (auto it = scene.ground.rbegin(); it != scene.ground.rend(); ++it) {
    if (geometry::point_in_polygon(it->points, point)) return it->cls;
  }
  return scene.ground_class;
}

class SceneBuildTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    scene_ = new StaticScene(build_static_scene(testing::cached_town("town02").net));
  }
  static void TearDownTestSuite() { delete scene_; }
  const RoadNetwork& net() const { return testing::cached_town("town02").net; }
  static StaticScene* scene_;
};
StaticScene* SceneBuildTest::scene_ = nullptr;

TEST_F(SceneBuildTest, RoadUnderEveryLaneAndSidewalkBesideIt) {
  int sidewalk_checks = 0;
  for (int l = 0; l < static_cast<int>(net().lanes().size()); ++l) {
    const Lane& lane = net().lane(l);
    for (double s = 0.0; s <= lane.length_m; s += 2.0) {
      const Pose2 pose = net().lane_pose(l, s);
      const Eigen::Vector2d centre(pose.x_m, pose.y_m);
      ASSERT_EQ(ground_class_at(*scene_, centre), SemanticClass::kRoad) << lane.id << " s=" << s;
      if (lane.internal || s < 15.0 || s > lane.length_m - 15.0) continue;
      // Right of a lane (away from the opposite direction): sidewalk up to 3 m, then terrain.
      const Eigen::Vector2d right(std::sin(pose.yaw_rad), -std::cos(pose.yaw_rad));
      EXPECT_EQ(ground_class_at(*scene_, centre + (0.5 * lane.width_m + 1.5) * right),
                SemanticClass::kSidewalk)
          << lane.id << " s=" << s;
      EXPECT_EQ(ground_class_at(*scene_, centre + (0.5 * lane.width_m + 4.5) * right),
                SemanticClass::kVegetation)
          << lane.id << " s=" << s;
      ++sidewalk_checks;
    }
  }
  EXPECT_GT(sidewalk_checks, 200);
}

TEST_F(SceneBuildTest, BoxesStandClearOfRoadsAndSidewalks) {
  int buildings = 0;
  int vegetation = 0;
  for (const Box& box : scene_->boxes) {
    buildings += box.cls == SemanticClass::kBuilding;
    vegetation += box.cls == SemanticClass::kVegetation;
    EXPECT_GT(box.height_m, 3.0);
    for (int corner = 0; corner < 4; ++corner) {
      const Eigen::Vector2d p(box.pose.x_m + ((corner & 1) ? 0.5 : -0.5) * box.length_m,
                              box.pose.y_m + ((corner & 2) ? 0.5 : -0.5) * box.width_m);
      for (const Lane& lane : net().lanes()) {
        const double clearance =
            geometry::project_polyline(lane.shape, lane.arc_m, p).distance_m - 0.5 * lane.width_m;
        // Sidewalk 3 m plus a 1 m setback (0.1 m slack for the sampled footprint test).
        ASSERT_GE(clearance, 3.9) << "box at " << box.pose.x_m << "," << box.pose.y_m;
      }
      EXPECT_NE(ground_class_at(*scene_, p), SemanticClass::kRoad);
    }
  }
  EXPECT_GT(buildings, 80);
  EXPECT_GT(vegetation, 20);
}

TEST_F(SceneBuildTest, CentreAndEdgeLines) {
  // Every normal edge is two-way with one lane: one centre line per pair, one edge line each.
  int edges = 0;
  for (const Edge& edge : net().edges()) edges += !edge.internal;
  EXPECT_EQ(scene_->lines.size(), static_cast<size_t>(edges / 2 + edges));
  // The road M1 (70, 80) - M3 (140, 80) has its centre line on y = 80 and edge lines 0.3 m
  // inside the road borders at y = 80 -+ 3.2.
  int centre = 0;
  int edge_lines = 0;
  for (const GroundLine& line : scene_->lines) {
    bool on_centre = true;
    bool on_edge = true;
    for (const auto& p : line.points) {
      on_centre &= std::abs(p.y() - 80.0) < 1e-6 && p.x() > 70.0 && p.x() < 140.0;
      on_edge &= std::abs(std::abs(p.y() - 80.0) - 3.2) < 1e-6 && p.x() > 70.0 && p.x() < 140.0;
    }
    centre += on_centre;
    edge_lines += on_edge;
    EXPECT_FALSE(line.dashed);
  }
  EXPECT_EQ(centre, 1);
  EXPECT_EQ(edge_lines, 2);
}

TEST_F(SceneBuildTest, DeterministicForASeed) {
  const StaticScene again = build_static_scene(net());
  ASSERT_EQ(again.boxes.size(), scene_->boxes.size());
  for (size_t i = 0; i < again.boxes.size(); ++i) {
    EXPECT_EQ(again.boxes[i].pose.x_m, scene_->boxes[i].pose.x_m);
    EXPECT_EQ(again.boxes[i].height_m, scene_->boxes[i].height_m);
    EXPECT_EQ(again.boxes[i].cls, scene_->boxes[i].cls);
  }
  SceneOptions other;
  other.seed = 2;
  const StaticScene reseeded = build_static_scene(net(), other);
  int differences = 0;
  for (size_t i = 0; i < std::min(reseeded.boxes.size(), again.boxes.size()); ++i) {
    differences += reseeded.boxes[i].height_m != again.boxes[i].height_m;
  }
  EXPECT_GT(differences, 10);
  // The scene's box covers the network with the margin around it.
  EXPECT_LT(scene_->min_corner.x(), net().min_corner().x() - 30.0);
  EXPECT_GT(scene_->max_corner.y(), net().max_corner().y() + 30.0);
}

TEST_F(SceneBuildTest, SpawnPointsLieOnLanesAwayFromJunctions) {
  const std::vector<SpawnPoint> spawns = spawn_points(net(), 15.0, 8.0);
  ASSERT_GT(spawns.size(), 50u);
  for (const SpawnPoint& spawn : spawns) {
    const Lane& lane = net().lane(spawn.lane);
    EXPECT_FALSE(lane.internal);
    EXPECT_EQ(spawn.lane_id, lane.id);
    EXPECT_GE(spawn.s_m, 8.0);
    EXPECT_LE(spawn.s_m, lane.length_m - 8.0);
    const Eigen::Vector2d p(spawn.pose.x_m, spawn.pose.y_m);
    const auto at = net().locate(p, spawn.pose.yaw_rad);
    ASSERT_TRUE(at.has_value());
    EXPECT_EQ(at->lane, spawn.lane);
    EXPECT_NEAR(at->lateral_m, 0.0, 1e-6);
    EXPECT_NEAR(wrap_angle(at->heading_rad - spawn.pose.yaw_rad), 0.0, 1e-9);
    EXPECT_FALSE(net().in_junction(p));
  }
  // Sparser spacing, fewer points.
  EXPECT_LT(spawn_points(net(), 30.0, 8.0).size(), spawns.size());
}

}  // namespace
}  // namespace indrive::env
