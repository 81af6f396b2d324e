#include "indrive/actor/eval_protocol.h"

#include <gtest/gtest.h>

#include <map>
#include <set>
#include <tuple>

namespace indrive::actor {
namespace {

TEST(ProtocolGrid, CoversEveryCellWithAllFifteenSeedPairs) {
  const ProtocolGrid grid{
      .towns = {"town01"}, .routes = {"straight"}, .densities = {10}, .episodes_per_cell = 15};
  const auto episodes = grid.all_episodes();
  ASSERT_EQ(episodes.size(), 15u);
  std::set<std::pair<int, int>> pairs;
  std::set<std::uint64_t> policy_seeds;
  for (const auto& e : episodes) {
    pairs.insert({e.traffic_seed, e.spawn_seed});
    policy_seeds.insert(e.policy_seed);
  }
  EXPECT_EQ(pairs.size(), 15u);
  EXPECT_EQ(policy_seeds.size(), 15u);
}

TEST(ProtocolGrid, DefaultGridIsThePapers) {
  const ProtocolGrid grid;
  EXPECT_EQ(grid.size(), 2 * 4 * 3 * 50);
  const auto episodes = grid.all_episodes();
  EXPECT_EQ(episodes.front().town, "town01");
  EXPECT_EQ(episodes.front().route, "straight");
  EXPECT_EQ(episodes.front().density, 5);
  EXPECT_EQ(episodes.back().town, "town02");
  EXPECT_EQ(episodes.back().route, "two_turn");
  EXPECT_EQ(episodes.back().density, 20);
  EXPECT_EQ(episodes.back().episode, 49);
}

TEST(ProtocolGrid, EvaluatorsSplitTheGridWithoutOverlapOrGaps) {
  const ProtocolGrid grid{.episodes_per_cell = 7};
  for (const int count : {1, 2, 3, 5}) {
    std::map<int, int> seen;
    for (int k = 0; k < count; ++k) {
      const auto mine = grid.episodes_for(k, count);
      // Balanced to within one episode.
      EXPECT_LE(std::abs(static_cast<int>(mine.size()) - grid.size() / count), 1);
      for (const auto& e : mine) ++seen[e.global_index];
    }
    ASSERT_EQ(static_cast<int>(seen.size()), grid.size()) << count << " evaluators";
    for (const auto& [index, times] : seen) EXPECT_EQ(times, 1) << index;
  }
}

TEST(ProtocolGrid, BadGridsAreClearErrors) {
  auto message = [](const ProtocolGrid& grid) {
    try {
      grid.validate();
    } catch (const std::invalid_argument& error) {
      return std::string(error.what());
    }
    return std::string();
  };
  EXPECT_NE(message({.densities = {5, 15}}).find("density 15 is not allowed"), std::string::npos);
  EXPECT_NE(message({.towns = {}}).find("towns list is empty"), std::string::npos);
  EXPECT_NE(message({.routes = {"straight", "straight"}}).find("duplicate"), std::string::npos);
  EXPECT_NE(message({.episodes_per_cell = 0}).find("at least 1"), std::string::npos);
  EXPECT_THROW(ProtocolGrid{}.episodes_for(2, 2), std::invalid_argument);
}

// A town's own routes (eval.routes: all): the CARLA towns have the public code's, not our four.
TEST(ProtocolGrid, ATownsOwnRoutesReplaceTheSharedList) {
  ProtocolGrid grid{.towns = {"town01", "carla_town02"}, .densities = {5}, .episodes_per_cell = 2};
  grid.town_routes["carla_town02"] = {"straight_1", "left_1", "two_turn_2"};
  EXPECT_EQ(grid.routes_of("town01").size(), 4u);
  EXPECT_EQ(grid.size(), (4 + 3) * 2);
  const auto episodes = grid.all_episodes();
  ASSERT_EQ(static_cast<int>(episodes.size()), grid.size());
  EXPECT_EQ(episodes[8].town, "carla_town02");
  EXPECT_EQ(episodes[8].route, "straight_1");
  EXPECT_EQ(episodes.back().route, "two_turn_2");
  grid.town_routes["carla_town02"] = {"left_1", "left_1"};
  EXPECT_THROW(grid.validate(), std::invalid_argument);
}

TEST(EvalProtocol, NamesParseBackAndAnUnknownOneSaysWhatExists) {
  for (const EvalProtocol p : {EvalProtocol::kStrict, EvalProtocol::kIndriveCode}) {
    EXPECT_EQ(parse_protocol(protocol_name(p)), p);
  }
  try {
    parse_protocol("carla");
    FAIL() << "an unknown protocol was taken";
  } catch (const EvalError& error) {
    EXPECT_NE(std::string(error.what()).find("strict (ours) or indrive_code"), std::string::npos)
        << error.what();
  }
}

}  // namespace
// A map given by path names result files by its stem: the local trainer's evaluation once
// tried to write eval/local-maps/x.xodr-straight.csv for env.town=maps/x.xodr.
TEST(TownFileLabel, BuiltInNamesStayAndPathsBecomeTheirStem) {
  EXPECT_EQ(town_file_label("town01"), "town01");
  EXPECT_EQ(town_file_label("maps/x.xodr"), "x");
  EXPECT_EQ(town_file_label("../my town.net.xml"), "my_town_net");
  EXPECT_EQ(town_file_label("/"), "_");
  EXPECT_EQ(town_file_label(""), "town");
}

}  // namespace indrive::actor
