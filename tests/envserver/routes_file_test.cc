// Route files: round trip and clear errors for broken files.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>

#include "indrive/envserver/routes.h"
#include "testing.h"

namespace indrive::env {
namespace {

using ::testing::HasSubstr;

std::string read_error(const std::filesystem::path& path) {
  try {
    read_route_file(path);
  } catch (const RouteError& error) {
    return error.what();
  }
  ADD_FAILURE() << "no RouteError for " << path;
  return {};
}

TEST(RoutesFileTest, RoundTrip) {
  indrive::testing::TempDir dir;
  const std::vector<RouteSpec> specs = {{"straight", false, {"a_b", "b_c"}},
                                        {"right_loop", true, {"x", "y", "z"}}};
  write_route_file(dir.path() / "r.yaml", specs);
  const std::vector<RouteSpec> back = read_route_file(dir.path() / "r.yaml");
  ASSERT_EQ(back.size(), 2u);
  EXPECT_EQ(back[0].name, "straight");
  EXPECT_FALSE(back[0].loop);
  EXPECT_EQ(back[0].edges, specs[0].edges);
  EXPECT_EQ(back[1].name, "right_loop");
  EXPECT_TRUE(back[1].loop);
  EXPECT_EQ(back[1].edges, specs[1].edges);
}

TEST(RoutesFileTest, BrokenFiles) {
  indrive::testing::TempDir dir;
  EXPECT_THAT(read_error(dir.path() / "missing.yaml"), HasSubstr("does not exist"));
  std::ofstream(dir.path() / "a.yaml") << "straight: [unclosed";
  EXPECT_THAT(read_error(dir.path() / "a.yaml"), HasSubstr("not valid YAML"));
  std::ofstream(dir.path() / "b.yaml") << "- just\n- a list\n";
  EXPECT_THAT(read_error(dir.path() / "b.yaml"), HasSubstr("must map route names"));
  std::ofstream(dir.path() / "c.yaml") << "straight: {loop: false}\n";
  EXPECT_THAT(read_error(dir.path() / "c.yaml"),
              HasSubstr("route 'straight' needs an 'edges' list"));
  std::ofstream(dir.path() / "d.yaml") << "straight: {loop: maybe, edges: [a]}\n";
  EXPECT_THAT(read_error(dir.path() / "d.yaml"), HasSubstr("route 'straight'"));
  std::ofstream(dir.path() / "e.yaml") << "straight: {edges: []}\n";
  EXPECT_THAT(read_error(dir.path() / "e.yaml"), HasSubstr("empty 'edges' list"));
  // A list as a key (found by tests/fuzz, target routes: it escaped as a yaml-cpp exception).
  std::ofstream(dir.path() / "f.yaml") << "? [a, b]\n: {edges: [x]}\n";
  EXPECT_THAT(read_error(dir.path() / "f.yaml"), HasSubstr("a route name must be plain text"));
}

TEST(RoutesFileTest, PointToPointRoutesRoundTripWithTheirFrameAndHeadings) {
  indrive::testing::TempDir dir;
  RouteSpec carla{.name = "right_1", .kind = "right"};
  carla.start = Eigen::Vector2d(391.86, 303.89);
  carla.end = Eigen::Vector2d(366.13, 325.66);
  carla.start_heading_rad = M_PI / 2;
  carla.end_heading_rad = M_PI;
  carla.frame = PointFrame::kCarla;
  RouteSpec net{
      .name = "east", .start = Eigen::Vector2d(10.0, -1.75), .end = Eigen::Vector2d(90.0, -1.75)};
  write_route_file(dir.path() / "r.yaml", {carla, net});
  const std::vector<RouteSpec> back = read_route_file(dir.path() / "r.yaml");
  ASSERT_EQ(back.size(), 2u);
  EXPECT_EQ(back[0].kind, "right");
  EXPECT_EQ(back[0].frame, PointFrame::kCarla);
  EXPECT_TRUE(back[0].start->isApprox(*carla.start));
  EXPECT_TRUE(back[0].end->isApprox(*carla.end));
  EXPECT_NEAR(*back[0].start_heading_rad, M_PI / 2, 1e-9);
  EXPECT_NEAR(*back[0].end_heading_rad, M_PI, 1e-9);
  EXPECT_TRUE(back[0].edges.empty());
  EXPECT_EQ(back[1].frame, PointFrame::kNetwork);
  EXPECT_FALSE(back[1].start_heading_rad.has_value());
  EXPECT_TRUE(back[1].end->isApprox(Eigen::Vector2d(90.0, -1.75)));
}

TEST(RoutesFileTest, BrokenPointToPointRoutes) {
  indrive::testing::TempDir dir;
  const auto error_of = [&](const std::string& text) {
    std::ofstream(dir.path() / "p.yaml") << text;
    return read_error(dir.path() / "p.yaml");
  };
  EXPECT_THAT(error_of("r: {carla_start: [1, 2]}\n"), HasSubstr("needs 'carla_end' as well"));
  EXPECT_THAT(error_of("r: {start: [1, 2], carla_end: [3, 4]}\n"), HasSubstr("give one pair"));
  EXPECT_THAT(error_of("r: {start: [1], end: [3, 4]}\n"),
              HasSubstr("must be a point [x, y] or [x, y, heading_deg]"));
  EXPECT_THAT(error_of("r: {start: [.nan, 2], end: [3, 4]}\n"), HasSubstr("finite coordinates"));
  EXPECT_THAT(error_of("r: {start: [1e300, 2], end: [3, 4]}\n"), HasSubstr("finite coordinates"));
  EXPECT_THAT(error_of("r: {start: [1, 2], end: [3, x]}\n"), HasSubstr("route 'r'"));
  EXPECT_THAT(error_of("r: {loop: true, start: [1, 2], end: [3, 4]}\n"),
              HasSubstr("a loop gives its edges"));
}

}  // namespace
}  // namespace indrive::env
