// Coverage on town02 with hand-built poses: pieces of lanes, distinct pieces per window, the
// CSV round trip and the map.
#include "indrive/envserver/coverage.h"

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <opencv2/imgcodecs.hpp>

#include "indrive/basics/run_dir.h"
#include "indrive/envserver/town.h"
#include "testing.h"

namespace indrive::env {
namespace {

const Town& town02() {
  static const Town town = load_town("town02");
  return town;
}

// The first normal lane at least `min_length_m` long.
int long_lane(double min_length_m) {
  const auto& lanes = town02().net.lanes();
  for (std::size_t i = 0; i < lanes.size(); ++i) {
    if (!lanes[i].internal && lanes[i].length_m >= min_length_m) return static_cast<int>(i);
  }
  ADD_FAILURE() << "town02 has no lane of " << min_length_m << " m";
  return 0;
}

TEST(LaneSegmentsTest, CutsEveryLaneIntoTenMetrePieces) {
  const RoadNetwork& net = town02().net;
  const LaneSegments segments(net, 10.0);
  int expected = 0;
  for (const Lane& lane : net.lanes()) {
    expected += std::max(1, static_cast<int>(std::ceil(lane.length_m / 10.0 - 1e-9)));
  }
  EXPECT_EQ(segments.count(), expected);
  const int lane = long_lane(35.0);
  const int first = segments.segment(lane, 0.0);
  EXPECT_EQ(segments.segment(lane, 9.9), first);
  EXPECT_EQ(segments.segment(lane, 10.1), first + 1);
  EXPECT_EQ(segments.segment(lane, 25.0), first + 2);
  EXPECT_EQ(segments.lane_of(first + 2), lane);
  EXPECT_EQ(segments.piece_of(first + 2), 2);
  EXPECT_EQ(segments.find(net.lane(lane).id, 2), first + 2);
  EXPECT_EQ(segments.find("no-such-lane", 0), -1);
  EXPECT_THROW(LaneSegments(net, 0.0), std::invalid_argument);
}

TEST(LaneSegmentsTest, LocatesPosesOnLanesAndJunctionsAndNotOffRoad) {
  const RoadNetwork& net = town02().net;
  const LaneSegments segments(net, 10.0);
  const int lane = long_lane(35.0);
  // On the lane centre, driving along it: the piece at that arc length.
  const Pose2 on_lane = net.lane_pose(lane, 15.0);
  ASSERT_TRUE(segments.locate(on_lane).has_value());
  EXPECT_EQ(*segments.locate(on_lane), segments.segment(lane, 15.0));
  // Far outside the town: no piece.
  const Pose2 off{net.max_corner().x() + 500.0, net.max_corner().y() + 500.0, 0.0};
  EXPECT_FALSE(segments.locate(off).has_value());
  // Junction-internal lanes count: the middle of some internal lane maps to an internal piece.
  int internal_hits = 0;
  for (std::size_t i = 0; i < net.lanes().size(); ++i) {
    const Lane& internal = net.lanes()[i];
    if (!internal.internal || internal.length_m < 4.0) continue;
    const auto piece = segments.locate(net.lane_pose(static_cast<int>(i), 0.5 * internal.length_m));
    if (piece && net.lane(segments.lane_of(*piece)).internal) ++internal_hits;
  }
  EXPECT_GT(internal_hits, 0);
}

// Poses on one long lane of town02: a and a2 on its first 10 m piece, b on the second, c on the
// fourth; off is far outside the town.
struct LanePoses {
  explicit LanePoses(const RoadNetwork& net)
      : lane(long_lane(35.0)),
        a(net.lane_pose(lane, 2.0)),
        a2(net.lane_pose(lane, 8.0)),
        b(net.lane_pose(lane, 12.0)),
        c(net.lane_pose(lane, 31.0)),
        off{net.max_corner().x() + 500.0, net.max_corner().y() + 500.0, 0.0} {}
  int lane;
  Pose2 a, a2, b, c, off;
};

TEST(CoverageTrackerTest, CountsDistinctPiecesPerWindow) {
  const RoadNetwork& net = town02().net;
  CoverageTracker coverage(net, {.segment_m = 10.0, .window_steps = 4});
  const LanePoses poses(net);
  const auto& [lane, a, a2, b, c, off] = poses;
  EXPECT_EQ(coverage.distinct_per_window(), 0.0);
  // Window 1: a, a2, b, off -> 2 distinct pieces.
  for (const Pose2& p : {a, a2, b, off}) coverage.observe(p);
  ASSERT_EQ(coverage.window_scores().size(), 1u);
  EXPECT_EQ(coverage.window_scores()[0], 2);
  // Window 2: b, c, c, c -> 2 distinct (b counts again in a new window).
  for (const Pose2& p : {b, c, c, c}) coverage.observe(p);
  ASSERT_EQ(coverage.window_scores().size(), 2u);
  EXPECT_EQ(coverage.window_scores()[1], 2);
  EXPECT_DOUBLE_EQ(coverage.distinct_per_window(), 2.0);
  // An incomplete window does not change the measure once a window is complete.
  coverage.observe(a);
  EXPECT_DOUBLE_EQ(coverage.distinct_per_window(), 2.0);
  EXPECT_EQ(coverage.steps(), 9);
  const LaneSegments& segments = coverage.segments();
  EXPECT_EQ(coverage.visits()[segments.segment(lane, 2.0)], 3);
  EXPECT_EQ(coverage.visits()[segments.segment(lane, 12.0)], 2);
  EXPECT_EQ(coverage.visits()[segments.segment(lane, 31.0)], 3);
  EXPECT_EQ(coverage.segments_visited(), 3);
  EXPECT_DOUBLE_EQ(coverage.fraction_visited(), 3.0 / segments.count());
}

TEST(CoverageTrackerTest, ReachCountsTheDistinctPiecesOfEachEpisode) {
  const RoadNetwork& net = town02().net;
  CoverageTracker coverage(net, {.segment_m = 10.0, .window_steps = 1000});
  const LanePoses poses(net);
  const auto& [lane, a, a2, b, c, off] = poses;
  coverage.end_episode();  // nothing observed yet: no episode
  EXPECT_TRUE(coverage.episode_reach().empty());
  // Episode 1 drives a -> b -> c (3 pieces in 5 steps, one off the road).
  for (const Pose2& p : {a, a2, b, off, c}) coverage.observe(p);
  coverage.end_episode();
  // Episode 2 is spawned on b again and ends there: 1 piece, although b was seen before.
  for (const Pose2& p : {b, b}) coverage.observe(p);
  coverage.end_episode();
  coverage.end_episode();  // twice in a row: still two episodes
  EXPECT_EQ(coverage.episode_reach(), (std::vector<int>{3, 1}));
  EXPECT_EQ(coverage.episode_steps(), (std::vector<int>{5, 2}));
  // The episode in progress is not counted until it ends.
  coverage.observe(c);
  EXPECT_EQ(coverage.episode_reach().size(), 2u);
}

TEST(CoverageTrackerTest, PartialWindowIsScaledToTheWindowLength) {
  const RoadNetwork& net = town02().net;
  CoverageTracker coverage(net, {.segment_m = 10.0, .window_steps = 1000});
  const int lane = long_lane(35.0);
  coverage.observe(net.lane_pose(lane, 1.0));
  coverage.observe(net.lane_pose(lane, 21.0));
  // 2 distinct pieces in 2 steps -> 1000 per 1000 steps.
  EXPECT_DOUBLE_EQ(coverage.distinct_per_window(), 1000.0);
}

TEST(CoverageCsvTest, RoundTripMergesFilesAndRejectsBadRows) {
  const RoadNetwork& net = town02().net;
  testing::TempDir dir;
  const int lane = long_lane(35.0);
  CoverageTracker first(net, {.segment_m = 10.0, .window_steps = 2});
  for (double s : {1.0, 2.0, 15.0, 15.0}) first.observe(net.lane_pose(lane, s));
  CoverageTracker second(net, {.segment_m = 10.0, .window_steps = 2});
  for (double s : {15.0, 25.0}) second.observe(net.lane_pose(lane, s));
  first.write_csv(dir.path() / "coverage" / "actor-0.csv");
  second.write_csv(dir.path() / "coverage" / "actor-1.csv");

  const CoverageCounts counts = read_coverage_csv(
      {dir.path() / "coverage" / "actor-0.csv", dir.path() / "coverage" / "actor-1.csv"});
  EXPECT_EQ(counts.steps, 6);
  EXPECT_EQ(counts.windows, 3);
  // Windows of 2 steps: first {piece 0} and {piece 1}, second {piece 1, piece 2}: (1 + 1 + 2) / 3.
  EXPECT_NEAR(counts.distinct_per_1k, 4.0 / 3.0, 1e-6);
  EXPECT_DOUBLE_EQ(counts.segment_m, 10.0);
  std::map<int, std::int64_t> by_piece;
  for (std::size_t i = 0; i < counts.pieces.size(); ++i) {
    EXPECT_EQ(counts.pieces[i].first, net.lane(lane).id);
    by_piece[counts.pieces[i].second] += counts.visits[i];
  }
  EXPECT_EQ(by_piece, (std::map<int, std::int64_t>{{0, 2}, {1, 3}, {2, 1}}));

  const auto bad = dir.path() / "bad.csv";
  std::ofstream(bad) << "lane,piece,visits\nlane_a,notanumber,3\n";
  EXPECT_THROW(read_coverage_csv({bad}), IoError);
  const auto wrong = dir.path() / "wrong.csv";
  std::ofstream(wrong) << "a,b\n1,2\n";
  EXPECT_THROW(read_coverage_csv({wrong}), IoError);
  EXPECT_THROW(read_coverage_csv({dir.path() / "missing.csv"}), IoError);
}

TEST(CoverageCsvTest, RestoreContinuesVisitsStepsAndWindows) {
  const RoadNetwork& net = town02().net;
  testing::TempDir dir;
  const int lane = long_lane(35.0);
  CoverageTracker first(net, {.segment_m = 10.0, .window_steps = 2});
  for (double s : {1.0, 12.0, 15.0, 15.0}) first.observe(net.lane_pose(lane, s));  // windows 2, 1
  first.write_csv(dir.path() / "coverage.csv");

  CoverageTracker resumed(net, {.segment_m = 10.0, .window_steps = 2});
  resumed.restore(read_coverage_csv({dir.path() / "coverage.csv"}));
  EXPECT_EQ(resumed.steps(), 4);
  EXPECT_DOUBLE_EQ(resumed.distinct_per_window(), 1.5);
  for (double s : {25.0, 31.0, 2.0}) resumed.observe(net.lane_pose(lane, s));  // window 2, part
  EXPECT_EQ(resumed.steps(), 7);
  EXPECT_DOUBLE_EQ(resumed.distinct_per_window(), (2.0 + 1.0 + 2.0) / 3.0);
  const LaneSegments& segments = resumed.segments();
  EXPECT_EQ(resumed.visits()[segments.segment(lane, 1.0)], 2);
  EXPECT_EQ(resumed.visits()[segments.segment(lane, 15.0)], 3);
  EXPECT_EQ(resumed.visits()[segments.segment(lane, 25.0)], 1);
  EXPECT_EQ(resumed.segments_visited(), 4);
  resumed.write_csv(dir.path() / "coverage.csv");
  const CoverageCounts counts = read_coverage_csv({dir.path() / "coverage.csv"});
  EXPECT_EQ(counts.steps, 7);
  EXPECT_EQ(counts.windows, 3);
}

TEST(CoverageMapTest, DrawsVisitedPiecesInColour) {
  const RoadNetwork& net = town02().net;
  testing::TempDir dir;
  CoverageTracker coverage(net);
  const int lane = long_lane(35.0);
  for (int i = 0; i < 50; ++i) coverage.observe(net.lane_pose(lane, 0.6 * i));
  coverage.write_csv(dir.path() / "coverage.csv");
  const auto png = dir.path() / "map.png";
  draw_coverage(net, read_coverage_csv({dir.path() / "coverage.csv"}), png, "test map");
  const cv::Mat image = cv::imread(png.string());
  ASSERT_FALSE(image.empty());
  // Some pixels are coloured (not grey, not white, not black): the visited pieces.
  int coloured = 0;
  for (int y = 40; y < image.rows; ++y) {
    for (int x = 0; x < image.cols - 110; ++x) {
      const cv::Vec3b p = image.at<cv::Vec3b>(y, x);
      if (std::abs(p[0] - p[1]) > 40 || std::abs(p[1] - p[2]) > 40) ++coloured;
    }
  }
  EXPECT_GT(coloured, 50);
}

}  // namespace
}  // namespace indrive::env
