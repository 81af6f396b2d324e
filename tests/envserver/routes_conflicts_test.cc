// The conflict rule: a policy that sees no route cannot leave one approach by two exits, so no
// two routes of a town may do so; every shipped route file keeps the rule. And the layout
// bound: what a policy that picks its exit by the exits a junction offers can follow.
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

// A T-junction j: "in" (eastbound, ends at x = 100) may go left ("up"), right ("down") or turn
// back ("back"); "up" continues to "top" with no other way on.
constexpr const char* kTeeNetwork = R"(<?xml version="1.0" encoding="UTF-8"?>
<net version="1.9">
  <edge id="in" from="a" to="j"><lane id="in_0" index="0" speed="10" length="100" width="3.2" shape="0,-1.6 100,-1.6"/></edge>
  <edge id="back" from="j" to="a"><lane id="back_0" index="0" speed="10" length="100" width="3.2" shape="100,1.6 0,1.6"/></edge>
  <edge id="up" from="j" to="n"><lane id="up_0" index="0" speed="10" length="100" width="3.2" shape="101.6,5 101.6,105"/></edge>
  <edge id="down" from="j" to="s"><lane id="down_0" index="0" speed="10" length="100" width="3.2" shape="98.4,-5 98.4,-105"/></edge>
  <edge id="top" from="n" to="t"><lane id="top_0" index="0" speed="10" length="100" width="3.2" shape="101.6,110 101.6,210"/></edge>
  <junction id="j" type="priority" x="100" y="0" shape="95,-5 105,-5 105,5 95,5"/>
  <connection from="in" to="up" fromLane="0" toLane="0" dir="l" state="M"/>
  <connection from="in" to="down" fromLane="0" toLane="0" dir="r" state="M"/>
  <connection from="in" to="back" fromLane="0" toLane="0" dir="t" state="M"/>
  <connection from="up" to="top" fromLane="0" toLane="0" dir="s" state="M"/>
</net>
)";

TEST(RouteChoicesTest, AJunctionsLayoutListsItsExitsWithoutTheUTurn) {
  const RoadNetwork net = RoadNetwork::parse(kTeeNetwork, "tee");
  const std::vector<RouteChoice> choices =
      route_choices(net, {{"left", false, {"in", "up", "top"}}, {"right", false, {"in", "down"}}});
  // "up" -> "top" has one way on: no choice.
  ASSERT_EQ(choices.size(), 2u);
  EXPECT_EQ(choices[0].route, "left");
  EXPECT_EQ(choices[0].approach, "in");
  EXPECT_EQ(choices[0].layout, "lr");
  EXPECT_EQ(choices[0].taken, 'l');
  EXPECT_EQ(choices[1].route, "right");
  EXPECT_EQ(choices[1].taken, 'r');
  // The U-turn is no exit a route may take, and unknown or unconnected edges are errors.
  EXPECT_THROW(route_choices(net, {{"u", false, {"in", "back"}}}), RouteError);
  EXPECT_THROW(route_choices(net, {{"x", false, {"in", "top"}}}), RouteError);
  EXPECT_THROW(route_choices(net, {{"y", false, {"nowhere", "up"}}}), RouteError);
}

TEST(LayoutRuleBoundTest, RoutesTakingDifferentExitsAtOneLayoutAreNotBothFollowed) {
  const std::vector<RouteChoice> choices = {
      {"straight", "a", "rs", 's'},   {"straight", "b", "ls", 's'},
      {"right", "c", "rs", 'r'},      {"right", "d", "lr", 'r'},
      {"keep_right", "e", "lr", 'r'}, {"keep_right", "f", "ls", 's'},
      {"keep_right", "g", "rs", 'r'},
  };
  const LayoutRuleBound bound =
      layout_rule_bound({"straight", "right", "keep_right", "no_junction"}, choices);
  EXPECT_EQ(bound.route_count, 4);
  // right and keep_right agree (lr -> r, ls -> s, rs -> r); a route without choices is
  // followed by any rule; straight clashes with both at {r,s}.
  EXPECT_EQ(bound.routes_followed,
            (std::vector<std::string>{"right", "keep_right", "no_junction"}));
  EXPECT_EQ(bound.rule, (std::map<std::string, char>{{"lr", 'r'}, {"ls", 's'}, {"rs", 'r'}}));
  ASSERT_EQ(bound.lookalikes.size(), 1u);
  EXPECT_THAT(bound.lookalikes[0], HasSubstr("{r,s}:"));
  EXPECT_THAT(bound.lookalikes[0], HasSubstr("straight goes straight (a)"));
  EXPECT_THAT(bound.lookalikes[0], HasSubstr("right turns right (c)"));
}

TEST(LayoutRuleBoundTest, ARouteThatTakesTwoExitsAtOneLayoutFollowsNoRule) {
  const LayoutRuleBound bound =
      layout_rule_bound({"zigzag"}, {{"zigzag", "a", "lr", 'l'}, {"zigzag", "b", "lr", 'r'}});
  EXPECT_TRUE(bound.routes_followed.empty());
  ASSERT_EQ(bound.lookalikes.size(), 1u);
  EXPECT_THAT(bound.lookalikes[0], HasSubstr("zigzag turns left (a), zigzag turns right (b)"));
  const LayoutRuleBound none = layout_rule_bound({}, {});
  EXPECT_EQ(none.route_count, 0);
  EXPECT_TRUE(none.routes_followed.empty());
}

// The built-in towns' routes follow the paper's kinds (a right loop, a left loop, a loop with
// both turns): on these grids of T-junctions a policy that picks its exit by layout follows
// one of the four, which bounds its average SR at 25% (docs/architecture.md, section 9).
TEST(LayoutRuleBoundTest, TheBuiltInTownsRoutesAreLookAlikes) {
  for (const std::string town_name : {"town01", "town02"}) {
    const Town& town = testing::cached_town(town_name);
    std::vector<std::string> names;
    for (const Route& route : town.routes) names.push_back(route.name());
    const std::vector<RouteChoice> choices = route_choices(town.net, town.routes);
    // straight crosses two T-junctions, one with a side road on each hand.
    std::vector<std::string> straight_layouts;
    for (const RouteChoice& choice : choices) {
      if (choice.route != "straight") continue;
      straight_layouts.push_back(choice.layout);
      EXPECT_EQ(choice.taken, 's') << town_name << " " << choice.approach;
    }
    EXPECT_EQ(straight_layouts, (std::vector<std::string>{"rs", "ls"})) << town_name;
    const LayoutRuleBound bound = layout_rule_bound(names, choices);
    EXPECT_EQ(bound.route_count, 4) << town_name;
    EXPECT_EQ(bound.routes_followed.size(), 1u) << town_name;
    EXPECT_EQ(bound.lookalikes.size(), 3u) << town_name;  // {l,r}, {l,s}, {r,s}
  }
}

}  // namespace
}  // namespace indrive::env
