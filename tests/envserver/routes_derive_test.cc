// Route derivation for networks without a route file.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <set>

#include "net_test_network.h"
#include "net_test_town.h"

namespace indrive::env {
namespace {

std::set<std::string> edge_set(const RouteSpec& spec) {
  return {spec.edges.begin(), spec.edges.end()};
}

TEST(RoutesDeriveTest, FindsTheSmallestBlockLoopsAndTheLongestCorridor) {
  const RoadNetwork& net = testing::cached_town("town02").net;
  const std::vector<RouteSpec> specs = derive_routes(net);
  ASSERT_EQ(specs.size(), 4u);
  for (size_t i = 0; i < specs.size(); ++i) EXPECT_EQ(specs[i].name, kRouteNames[i]);
  // The longest corridor without a bend, the cross road x = 70 m (three edges), goes straight
  // at M1 where the right loop turns right at the same layout; derivation takes the longest
  // that lets one layout rule follow it and the right loop: the cross road y = 80 m, westbound.
  EXPECT_FALSE(specs[0].loop);
  EXPECT_EQ(specs[0].edges, (std::vector<std::string>{"E1_M3", "M3_M1"}));
  // The smallest block (x 140..200, y 150..200) clockwise and counter-clockwise.
  EXPECT_EQ(edge_set(specs[1]), (std::set<std::string>{"N2_E2", "E2_M4", "M4_N2"}));
  EXPECT_EQ(edge_set(specs[2]), (std::set<std::string>{"E2_N2", "N2_M4", "M4_E2"}));
  // The derived specs build valid routes of the right kinds.
  const std::vector<Route> routes = build_routes(net, specs);
  for (TurnDirection turn : routes[1].turns()) EXPECT_FALSE(is_left_turn(turn));
  for (TurnDirection turn : routes[2].turns()) EXPECT_FALSE(is_right_turn(turn));
  bool right = false;
  bool left = false;
  for (TurnDirection turn : routes[3].turns()) {
    right |= is_right_turn(turn);
    left |= is_left_turn(turn);
  }
  EXPECT_TRUE(right && left);
  // Loops start on their longest edge, for a run-up before the first turn.
  for (size_t r = 1; r < routes.size(); ++r) {
    double longest = 0.0;
    for (const std::string& id : specs[r].edges) {
      longest = std::max(longest, net.lane(net.edge(net.find_edge(id)).lanes[0]).length_m);
    }
    EXPECT_DOUBLE_EQ(net.lane(net.edge(net.find_edge(specs[r].edges[0])).lanes[0]).length_m,
                     longest);
  }
}

TEST(RoutesDeriveTest, PrefersConflictFreeSets) {
  // On town02 the shortest mixed loop leaves E2_M4 to M4_M3 where right_loop leaves it to
  // M4_N2; derivation takes the next candidate that keeps the set conflict-free.
  for (const std::string town : {"town01", "town02", "grid:3"}) {
    const RoadNetwork& net = testing::cached_town(town).net;
    const std::vector<RouteSpec> specs = derive_routes(net);
    ASSERT_EQ(specs.size(), 4u) << town;
    for (const RouteConflict& conflict : route_conflicts(specs)) {
      ADD_FAILURE() << town << ": " << conflict.message;
    }
    // Still valid routes of their kinds.
    const std::vector<Route> routes = build_routes(net, specs);
    for (TurnDirection turn : routes[0].turns()) EXPECT_EQ(turn, TurnDirection::kStraight);
    for (TurnDirection turn : routes[1].turns()) EXPECT_FALSE(is_left_turn(turn)) << town;
    for (TurnDirection turn : routes[2].turns()) EXPECT_FALSE(is_right_turn(turn)) << town;
    bool right = false;
    bool left = false;
    for (TurnDirection turn : routes[3].turns()) {
      right |= is_right_turn(turn);
      left |= is_left_turn(turn);
    }
    EXPECT_TRUE(right && left) << town;
  }
}

TEST(RoutesDeriveTest, PrefersSetsMoreRoutesOfWhichOneLayoutRuleFollows) {
  // On the built-in towns no layout rule follows more than two of the four kinds
  // (routes_conflicts_test.cc); the derived sets reach two. On a grid of crossroads every route
  // meets the layout {l,r,s} and the kinds take each exit there: one.
  for (const auto& [town, most] :
       std::vector<std::pair<std::string, size_t>>{{"town01", 2}, {"town02", 2}, {"grid:3", 1}}) {
    const RoadNetwork& net = testing::cached_town(town).net;
    const std::vector<RouteSpec> specs = derive_routes(net);
    std::vector<std::string> names;
    for (const RouteSpec& spec : specs) names.push_back(spec.name);
    const LayoutRuleBound bound = layout_rule_bound(names, route_choices(net, specs));
    EXPECT_EQ(bound.routes_followed.size(), most) << town;
    EXPECT_TRUE(route_conflicts(specs).empty()) << town;
  }
}

TEST(RoutesDeriveTest, NetworkWithoutLoopsNamesWhatIsMissing) {
  const RoadNetwork net = RoadNetwork::parse(testing::kHandNetwork, "hand");
  try {
    derive_routes(net);
    FAIL() << "expected RouteError";
  } catch (const RouteError& error) {
    EXPECT_THAT(error.what(), ::testing::HasSubstr("right_loop left_loop two_turn"));
    EXPECT_THAT(error.what(), ::testing::Not(::testing::HasSubstr("straight")));
  }
}

}  // namespace
}  // namespace indrive::env
