#include "indrive/envserver/route_check.h"

#include <gtest/gtest.h>

#include <map>
#include <set>

#include "indrive/envserver/town.h"

namespace indrive::env {
namespace {

TEST(RouteCheck, TheScriptedFollowerDrivesEveryShippedRouteOfOurTowns) {
  for (const std::string name : {"town01", "town02"}) {
    const Town town = load_town(name);
    for (const Route& route : town.routes) {
      EXPECT_EQ(oracle_drive_failure(town.net, route.spec()), "") << name << " " << route.name();
    }
  }
}

TEST(RouteCheck, ARouteThatDoesNotFitTheNetworkIsNamedSo) {
  const Town town = load_town("town01");
  const std::string why = oracle_drive_failure(town.net, {"straight", false, {"no_such_edge"}});
  EXPECT_EQ(why.rfind("does not fit the network", 0), 0u) << why;
}

// The filter is asked in rank order; a refused candidate is replaced by the next one of its
// kind and reported with its reason.
TEST(RouteCheck, DerivationReplacesRefusedCandidatesAndReportsThem) {
  const Town town = load_town("town01");
  const std::vector<RouteSpec> unfiltered = derive_routes(town.net);
  // Refuse exactly the routes the unfiltered derivation chose.
  std::set<std::vector<std::string>> refused_edges;
  for (const RouteSpec& spec : unfiltered) refused_edges.insert(spec.edges);
  std::vector<DroppedRoute> dropped;
  const std::vector<RouteSpec> filtered = derive_routes(
      town.net,
      [&](const RouteSpec& spec) {
        return refused_edges.count(spec.edges) ? std::string("refused by the test") : "";
      },
      &dropped);
  ASSERT_EQ(filtered.size(), unfiltered.size());
  for (const RouteSpec& spec : filtered) {
    EXPECT_EQ(refused_edges.count(spec.edges), 0u) << spec.name << " kept a refused candidate";
  }
  std::map<std::string, int> dropped_per_kind;
  for (const DroppedRoute& route : dropped) {
    EXPECT_EQ(route.reason, "refused by the test");
    ++dropped_per_kind[route.spec.name];
  }
  for (const RouteSpec& spec : unfiltered) EXPECT_GE(dropped_per_kind[spec.name], 1) << spec.name;

  // A kind with no usable candidate is named, with the first reason.
  try {
    derive_routes(town.net, [](const RouteSpec& spec) {
      return spec.name == "left_loop" ? std::string("lane_invasion at 25% of the route") : "";
    });
    FAIL() << "expected RouteError";
  } catch (const RouteError& error) {
    const std::string what = error.what();
    EXPECT_NE(what.find("left_loop"), std::string::npos) << what;
    EXPECT_NE(what.find("lane_invasion at 25%"), std::string::npos) << what;
    EXPECT_EQ(what.find("right_loop"), std::string::npos) << what;
  }
}

}  // namespace
}  // namespace indrive::env
