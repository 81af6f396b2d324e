// Built-in towns: their layout, drivability of every turn, conversion cache, other map sources
// and the errors for bad specs.
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <fstream>
#include <map>
#include <set>
#include <thread>

#include "indrive/envserver/net_geometry.h"
#include "net_test_town.h"
#include "testing.h"

namespace indrive::env {
namespace {

using ::testing::HasSubstr;
namespace fs = std::filesystem;

// The ego's tightest turn: wheelbase 2.9 m / tan(0.3 * 70 deg) = 7.55 m; allow 0.1 m of
// path-following slack.
constexpr double kEgoTurnRadiusM = 7.45;

// Smallest radius of the circle through points kChordM apart along a polyline: the sharpest
// bend a vehicle tracking it must take. The chord is longer than netconvert's ~3 m segments,
// so a single joint (a polyline's stand-in for a smooth arc) does not read as a sharp bend.
double min_turn_radius(const std::vector<Eigen::Vector2d>& points) {
  constexpr double kChordM = 4.0;
  const std::vector<double> arc = geometry::arc_lengths(points);
  double smallest = std::numeric_limits<double>::infinity();
  for (double s = 0.0; s + 2 * kChordM <= arc.back(); s += 0.25) {
    const Eigen::Vector2d a = geometry::point_at(points, arc, s, nullptr);
    const Eigen::Vector2d b = geometry::point_at(points, arc, s + kChordM, nullptr);
    const Eigen::Vector2d c = geometry::point_at(points, arc, s + 2 * kChordM, nullptr);
    const double cross = std::abs((b - a).x() * (c - a).y() - (b - a).y() * (c - a).x());
    if (cross < 1e-9) continue;
    smallest = std::min(smallest, (b - a).norm() * (c - b).norm() * (c - a).norm() / (2 * cross));
  }
  return smallest;
}

class BuiltInTownTest : public ::testing::TestWithParam<std::string> {};

TEST_P(BuiltInTownTest, LayoutHasTheCharacterOfItsModel) {
  const Town& town = testing::cached_town(GetParam());
  const RoadNetwork& net = town.net;
  const Eigen::Vector2d extent = net.max_corner() - net.min_corner();
  if (GetParam() == "town01") {
    EXPECT_NEAR(extent.x(), 400.0, 10.0);
    EXPECT_NEAR(extent.y(), 330.0, 10.0);
  } else {
    EXPECT_NEAR(extent.x(), 200.0, 10.0);
    EXPECT_NEAR(extent.y(), 200.0, 10.0);
  }
  // Every junction is a T: three roads meet (three incoming edges), never four.
  std::map<std::string, int> incoming;
  for (const Edge& edge : net.edges()) {
    if (edge.internal) continue;
    ++incoming[edge.to_junction];
    // One lane per direction, 3.5 m wide, and every road two-way.
    ASSERT_EQ(edge.lanes.size(), 1u) << edge.id;
    EXPECT_DOUBLE_EQ(net.lane(edge.lanes[0]).width_m, 3.5) << edge.id;
    bool has_opposite = false;
    for (const Edge& other : net.edges()) {
      has_opposite |=
          other.from_junction == edge.to_junction && other.to_junction == edge.from_junction;
    }
    EXPECT_TRUE(has_opposite) << edge.id;
  }
  EXPECT_FALSE(incoming.empty());
  for (const auto& [junction, count] : incoming) EXPECT_EQ(count, 3) << junction;
  // No U-turns.
  for (const Connection& connection : net.connections()) {
    EXPECT_NE(connection.direction, TurnDirection::kTurnaround);
  }
}

TEST_P(BuiltInTownTest, EveryTurnIsWithinTheEgosSteeringReach) {
  const RoadNetwork& net = testing::cached_town(GetParam()).net;
  int turns = 0;
  for (const Connection& connection : net.connections()) {
    // The whole crossing, with a little of the lanes before and after it.
    std::vector<Eigen::Vector2d> path;
    const Lane& from = net.lane(connection.from_lane);
    path.push_back(from.shape[from.shape.size() - 2]);
    for (int lane : net.crossing_lanes(connection)) {
      for (const auto& p : net.lane(lane).shape) path.push_back(p);
    }
    path.push_back(net.lane(connection.to_lane).shape[1]);
    path = geometry::dedupe(path, 1e-3);
    EXPECT_GE(min_turn_radius(path), kEgoTurnRadiusM)
        << net.lane(connection.from_lane).id << " -> " << net.lane(connection.to_lane).id;
    turns += connection.direction != TurnDirection::kStraight;
  }
  EXPECT_GT(turns, 10);
  // The ring's corners are curves inside edges.
  for (const Lane& lane : net.lanes()) {
    if (!lane.internal) {
      EXPECT_GE(min_turn_radius(lane.shape), kEgoTurnRadiusM) << lane.id;
    }
  }
}

TEST_P(BuiltInTownTest, HasFourRoutesAndSpawnPoints) {
  const Town& town = testing::cached_town(GetParam());
  ASSERT_EQ(town.routes.size(), 4u);
  for (size_t i = 0; i < kRouteNames.size(); ++i) EXPECT_EQ(town.routes[i].name(), kRouteNames[i]);
  EXPECT_GT(town.spawns.size(), 50u);
}

INSTANTIATE_TEST_SUITE_P(Towns, BuiltInTownTest, ::testing::Values("town01", "town02"));

TEST(TownResolveTest, ConversionIsCachedByContent) {
  indrive::testing::TempDir dir;
  TownOptions options;
  options.cache_dir = dir.path() / "cache";
  options.data_dir = dir.path() / "data";
  fs::create_directories(options.data_dir / "towns");
  for (const char* file : {"town02.nod.xml", "town02.edg.xml"}) {
    fs::copy_file(indrive::testing::source_path(std::string("envserver/data/towns/") + file),
                  options.data_dir / "towns" / file);
  }
  const fs::path first = resolve_town_network("town02", options);
  ASSERT_TRUE(fs::is_regular_file(first));
  const auto written = fs::last_write_time(first);
  // Same content: the cached file is reused untouched.
  EXPECT_EQ(resolve_town_network("town02", options), first);
  EXPECT_EQ(fs::last_write_time(first), written);
  // Edited source: a new conversion under a new name.
  std::ofstream(options.data_dir / "towns" / "town02.nod.xml", std::ios::app) << "<!-- edit -->\n";
  const fs::path second = resolve_town_network("town02", options);
  EXPECT_NE(second, first);
  EXPECT_TRUE(fs::is_regular_file(second));
  // No temporary files are left behind.
  int files = 0;
  for (const auto& entry : fs::directory_iterator(options.cache_dir)) {
    ++files;
    EXPECT_THAT(entry.path().string(), ::testing::EndsWith(".net.xml"));
    EXPECT_THAT(entry.path().string(), ::testing::Not(HasSubstr(".tmp.")));
  }
  EXPECT_EQ(files, 2);
}

TEST(TownResolveTest, ConcurrentConversionsAgree) {
  // Actors started together all convert the same town into one cache folder.
  indrive::testing::TempDir dir;
  TownOptions options;
  options.cache_dir = dir.path();
  std::vector<fs::path> results(4);
  std::vector<std::thread> threads;
  for (size_t i = 0; i < results.size(); ++i) {
    threads.emplace_back([&, i] { results[i] = resolve_town_network("town02", options); });
  }
  for (auto& thread : threads) thread.join();
  for (const auto& result : results) EXPECT_EQ(result, results[0]);
  EXPECT_EQ(RoadNetwork::load(results[0]).lanes().size(), 100u);
  int files = 0;
  for (const auto& entry : fs::directory_iterator(dir.path())) {
    ++files;
    EXPECT_EQ(entry.path(), results[0]);
  }
  EXPECT_EQ(files, 1);
}

TEST(TownResolveTest, UserNetworkAndOpenDriveAndGrid) {
  const TownOptions options = testing::test_town_options();
  // A user .net.xml is used in place; its routes are derived.
  const fs::path net_file = resolve_town_network("town02", options);
  EXPECT_EQ(resolve_town_network(net_file.string(), options), net_file);
  const Town user = load_town(net_file.string(), options);
  EXPECT_EQ(user.routes.size(), 4u);

  // OpenDRIVE: export town02 as .xodr, then load it back through netconvert.
  indrive::testing::TempDir dir;
  const fs::path xodr = dir.path() / "exported.xodr";
  const std::string command = std::string(INDRIVE_NETCONVERT_FOR_TESTS) +
                              " --xml-validation never -s " + net_file.string() +
                              " --opendrive-output " + xodr.string() + " > /dev/null 2>&1";
  ASSERT_EQ(std::system(command.c_str()), 0) << command;
  TownOptions xodr_options = options;
  xodr_options.cache_dir = dir.path() / "cache";
  const Town from_xodr = load_town(xodr.string(), xodr_options);
  EXPECT_EQ(from_xodr.net.lanes().size(), user.net.lanes().size());
  EXPECT_NEAR(from_xodr.routes[1].length_m(), user.routes[1].length_m(), 1.0);

  // A procedural grid town.
  const Town grid = load_town("grid:3", options);
  EXPECT_EQ(grid.routes.size(), 4u);
  EXPECT_GT(grid.net.junctions().size(), 9u);
}

std::string resolve_error(const std::string& spec, const TownOptions& options) {
  try {
    resolve_town_network(spec, options);
  } catch (const MapError& error) {
    return error.what();
  }
  ADD_FAILURE() << "no MapError for " << spec;
  return {};
}

TEST(TownResolveTest, BadSpecsSayWhatIsWrong) {
  indrive::testing::TempDir dir;
  TownOptions options;
  options.cache_dir = dir.path() / "cache";
  options.data_dir = dir.path() / "data";
  EXPECT_THAT(resolve_error("town99", options), HasSubstr("unknown town 'town99'"));
  EXPECT_THAT(resolve_error("town99", options), HasSubstr("town01, town02"));
  EXPECT_THAT(resolve_error("/nowhere/x.net.xml", options), HasSubstr("does not exist"));
  EXPECT_THAT(resolve_error("/nowhere/x.xodr", options), HasSubstr("OpenDRIVE file"));
  EXPECT_THAT(resolve_error("grid:seven", options), HasSubstr("grid:<seed>"));
  // Built-in sources missing from the data folder.
  EXPECT_THAT(resolve_error("town01", options), HasSubstr("INDRIVE_ENV_DATA_DIR"));
  // A malformed source: netconvert's own complaint comes through.
  fs::create_directories(options.data_dir / "towns");
  std::ofstream(options.data_dir / "towns" / "town01.nod.xml") << "<nodes><node id='a' x='oops'/>";
  std::ofstream(options.data_dir / "towns" / "town01.edg.xml") << "<edges/>";
  EXPECT_THAT(resolve_error("town01", options), HasSubstr("failed to convert town01"));
  // A missing converter program.
  fs::copy_file(indrive::testing::source_path("envserver/data/towns/town02.nod.xml"),
                options.data_dir / "towns" / "town02.nod.xml");
  fs::copy_file(indrive::testing::source_path("envserver/data/towns/town02.edg.xml"),
                options.data_dir / "towns" / "town02.edg.xml");
  options.netconvert = "/nonexistent/netconvert";
  EXPECT_THAT(resolve_error("town02", options), HasSubstr("could not run"));
}

}  // namespace
}  // namespace indrive::env
