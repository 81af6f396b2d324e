// Route files: round trip and clear errors for broken files.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

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

}  // namespace
}  // namespace indrive::env
