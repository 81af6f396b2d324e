#include "indrive/deploy/plot.h"

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <opencv2/imgcodecs.hpp>

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

}  // namespace
}  // namespace indrive::deploy
