// The conflict rule: a policy that sees no route cannot leave one approach by two exits, so no
// two routes of a town may do so; every shipped route file keeps the rule.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>

#include "net_test_town.h"

namespace indrive::env {
namespace {

using ::testing::HasSubstr;

TEST(RouteConflictsTest, OppositeExitsOfOneApproachAreReportedWithBothRoutes) {
  // Two loops share the approach "in" and leave it to the right and to the left.
  const std::vector<RouteSpec> specs = {
      {"right", true, {"in", "r1", "r2"}},
      {"left", true, {"l1", "l2", "in", "l3"}},
  };
  const std::vector<RouteConflict> conflicts = route_conflicts(specs);
  ASSERT_EQ(conflicts.size(), 1u);
  const RouteConflict& c = conflicts[0];
  EXPECT_EQ(c.approach, "in");
  EXPECT_EQ(c.route_a, "right");
  EXPECT_EQ(c.exit_a, "r1");
  EXPECT_EQ(c.route_b, "left");
  EXPECT_EQ(c.exit_b, "l3");
  EXPECT_THAT(c.message, HasSubstr("approach in"));
  EXPECT_THAT(c.message, HasSubstr("right leaves it to r1"));
  EXPECT_THAT(c.message, HasSubstr("left to l3"));
}

TEST(RouteConflictsTest, ALoopsClosingPairCounts) {
  // The loop's closing pair is c -> a; the corridor leaves c to d.
  const std::vector<RouteSpec> specs = {{"loop", true, {"a", "b", "c"}},
                                        {"corridor", false, {"x", "c", "d"}}};
  const std::vector<RouteConflict> conflicts = route_conflicts(specs);
  ASSERT_EQ(conflicts.size(), 1u);
  EXPECT_EQ(conflicts[0].approach, "c");
  EXPECT_EQ(conflicts[0].exit_a, "a");
  EXPECT_EQ(conflicts[0].exit_b, "d");
  // A corridor's last edge has no exit: ending on an approach is no conflict.
  EXPECT_TRUE(
      route_conflicts({{"loop", true, {"a", "b", "c"}}, {"corridor", false, {"x", "c"}}}).empty());
}

TEST(RouteConflictsTest, SharedApproachesWithTheSameExitAreConsistent) {
  const std::vector<RouteSpec> specs = {
      {"straight", false, {"s1", "s2", "s3"}},
      {"loop", true, {"s2", "s3", "t1", "t2"}},  // leaves s2 to s3 like the corridor
      {"other", true, {"u1", "u2", "u3"}},
  };
  EXPECT_TRUE(route_conflicts(specs).empty());
  EXPECT_TRUE(route_conflicts(std::vector<RouteSpec>{}).empty());
}

TEST(RouteConflictsTest, EveryShippedRouteFileIsConflictFree) {
  namespace fs = std::filesystem;
  const fs::path folder = fs::path(INDRIVE_SOURCE_DIR) / "envserver" / "data" / "routes";
  std::vector<fs::path> files;
  for (const auto& entry : fs::directory_iterator(folder)) {
    const std::string name = entry.path().filename().string();
    if (name.size() > 12 && name.ends_with(".routes.yaml")) files.push_back(entry.path());
  }
  std::sort(files.begin(), files.end());
  ASSERT_GE(files.size(), 2u) << "no route files found under " << folder;
  for (const fs::path& file : files) {
    const std::vector<RouteSpec> specs = read_route_file(file);
    for (const RouteConflict& conflict : route_conflicts(specs)) {
      ADD_FAILURE() << file.filename() << ": " << conflict.message;
    }
    // A built-in town's file also builds on its network, and the town loads conflict-free.
    const std::string town = file.filename().string().substr(0, file.filename().string().find('.'));
    const auto builtin = builtin_towns();
    if (std::find(builtin.begin(), builtin.end(), town) != builtin.end()) {
      EXPECT_TRUE(route_conflicts(testing::cached_town(town).routes).empty()) << town;
    }
  }
}

}  // namespace
}  // namespace indrive::env
