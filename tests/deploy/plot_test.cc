#include "indrive/deploy/plot.h"

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <opencv2/imgcodecs.hpp>

#include "indrive/envserver/coverage.h"
#include "indrive/envserver/town.h"
#include "testing.h"

namespace indrive::deploy {
namespace {

TEST(NiceTicks, UseOneTwoFiveSteps) {
  EXPECT_EQ(nice_ticks(0, 10, 5), (std::vector<double>{0, 2, 4, 6, 8, 10}));
  EXPECT_EQ(nice_ticks(0.3, 1.7, 3), (std::vector<double>{0.5, 1.0, 1.5}));
  EXPECT_EQ(nice_ticks(-1000, 5000, 6),
            (std::vector<double>{-1000, 0, 1000, 2000, 3000, 4000, 5000}));
}

TEST(LinePlot, DrawsEachSeriesInItsColourInsideTheAxes) {
  LinePlot plot("loss", "steps", "value");
  plot.add_series("rising", {0, 1, 2, 3}, {0, 1, 2, 3});
  const cv::Mat image = plot.render(400, 300);
  ASSERT_EQ(image.rows, 300);
  // The first colour (BGR 180,119,31) appears; a plot of nothing shows none of it.
  auto count_colour = [](const cv::Mat& m) {
    int n = 0;
    for (int r = 0; r < m.rows; ++r)
      for (int c = 0; c < m.cols; ++c) n += m.at<cv::Vec3b>(r, c) == cv::Vec3b(180, 119, 31);
    return n;
  };
  EXPECT_GT(count_colour(image), 100);
  LinePlot empty("loss", "steps", "value");
  EXPECT_EQ(count_colour(empty.render(400, 300)), 0);
  EXPECT_THROW(plot.add_series("bad", {0, 1}, {0}), std::invalid_argument);
}

TEST(PlotMetrics, WritesOnePngPerNumericKeyAndToleratesACutLastLine) {
  testing::TempDir dir;
  const auto metrics = dir.path() / "metrics.jsonl";
  {
    std::ofstream out(metrics);
    for (int i = 0; i < 20; ++i) {
      out << "{\"env_steps\": " << i * 100 << ", \"wm_loss\": " << std::exp(-0.1 * i)
          << ", \"phase\": \"pretrain\", \"time\": 1}\n";
    }
    out << "{\"env_steps\": 2000, \"wm_lo";  // crash mid-line
  }
  const auto files = plot_metrics(metrics, dir.path() / "plots");
  ASSERT_EQ(files.size(), 1u);
  EXPECT_EQ(files[0].filename(), "wm_loss.png");
  EXPECT_FALSE(cv::imread(files[0].string()).empty());
}

TEST(CoverageMap, MergesActorFilesOfARunOnItsTrainingTown) {
  testing::TempDir dir;
  const auto run = dir.path() / "run";
  std::filesystem::create_directories(run);
  EXPECT_FALSE(plot_coverage(run, run / "plots" / "coverage_map.png").has_value());

  std::ofstream(run / "config.yaml") << "env:\n  town: town02\n";
  const env::Town town = env::load_town("town02");
  int lane = 0;
  while (town.net.lane(lane).internal || town.net.lane(lane).length_m < 30.0) ++lane;
  for (int actor = 0; actor < 2; ++actor) {
    env::CoverageTracker coverage(town.net);
    for (int i = 0; i < 20; ++i) coverage.observe(town.net.lane_pose(lane, 1.5 * i));
    coverage.write_csv(run / "coverage" / ("actor-" + std::to_string(actor) + ".csv"));
  }
  const auto png = plot_coverage(run, run / "plots" / "coverage_map.png");
  ASSERT_TRUE(png.has_value());
  const cv::Mat image = cv::imread(png->string());
  ASSERT_FALSE(image.empty());
  EXPECT_GT(image.cols, 300);

  // A run whose config names a town that does not exist is an error naming it.
  std::ofstream(run / "config.yaml") << "env:\n  town: no_such_town\n";
  EXPECT_THROW(plot_coverage(run, run / "plots" / "coverage_map.png"), env::MapError);
}

}  // namespace
}  // namespace indrive::deploy
