#include "indrive/deploy/plot.h"

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <sstream>

#include "indrive/basics/run_dir.h"
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

TEST(MetricsFollower, ReadsOnlyCompleteAppendedLinesAndStartsAgainOnAShorterFile) {
  testing::TempDir dir;
  const auto path = dir.path() / "metrics.jsonl";
  MetricsFollower follower(path);
  EXPECT_TRUE(follower.update().empty());  // no file yet: no lines yet
  std::ofstream out(path);
  out << "{\"env_steps\": 1, \"a\": 10}\n{\"env_steps\": 2, \"a\": 20}\n{\"env_steps\": 3, \"a\""
      << std::flush;
  EXPECT_EQ(follower.update().at("a").second, (std::vector<double>{10, 20}));
  // The line being written is read once its newline is there, and only the new part is parsed.
  out << ": 30}\n" << std::flush;
  EXPECT_EQ(follower.update().at("a").second, (std::vector<double>{10, 20, 30}));
  EXPECT_EQ(follower.update().at("a").first, (std::vector<double>{1, 2, 3}));
  // A corrupt complete line is an error naming its line, as read_metric_columns says.
  out << "{oops\n{\"env_steps\": 5, \"a\": 50}\n" << std::flush;
  EXPECT_NE(
      testing::error_of<IoError>([&] { follower.update(); }).find("metrics.jsonl:4: not JSON"),
      std::string::npos);
  out.close();
  // A new run in the same folder: a shorter file is read from its start.
  std::ofstream(path) << "{\"env_steps\": 7, \"a\": 70}\n";
  MetricsFollower again(path);
  again.update();
  std::ofstream(path) << "{\"env_steps\": 8, \"b\": 1}\n";
  const auto& columns = again.update();
  EXPECT_FALSE(columns.contains("a"));
  EXPECT_EQ(columns.at("b").first, (std::vector<double>{8}));
}

TEST(PlotCompare, DrawsOneSeriesPerRunAndNamesARunWithoutTheMetric) {
  testing::TempDir dir;
  const auto write_run = [&](const std::string& name, double slope, bool with_metric) {
    const auto run = dir.path() / name;
    std::filesystem::create_directories(run);
    std::ofstream out(run / "metrics.jsonl");
    for (int i = 0; i < 10; ++i) {
      out << "{\"env_steps\": " << i * 1000;
      if (with_metric) out << ", \"coverage_fraction_visited\": " << slope * i;
      out << "}\n";
    }
    return run;
  };
  const auto random = write_run("random", 0.02, true);
  const auto disag = write_run("disag", 0.03, true);
  const auto png = dir.path() / "out" / "coverage.png";
  const auto ends = plot_compare({single_run_group(random), single_run_group(disag)},
                                 "coverage_fraction_visited", png);
  ASSERT_EQ(ends.size(), 2u);
  EXPECT_EQ(ends[1].label, "disag");
  EXPECT_DOUBLE_EQ(ends[1].x, 9000);
  EXPECT_NEAR(ends[1].y, 0.27, 1e-12);
  EXPECT_EQ(ends[1].low, ends[1].high);
  const cv::Mat image = cv::imread(png.string());
  ASSERT_FALSE(image.empty());
  // Both series' colours (the first two of the palette, BGR) are drawn.
  auto count_colour = [&](cv::Vec3b colour) {
    int n = 0;
    for (int r = 0; r < image.rows; ++r)
      for (int c = 0; c < image.cols; ++c) n += image.at<cv::Vec3b>(r, c) == colour;
    return n;
  };
  EXPECT_GT(count_colour({180, 119, 31}), 50);
  EXPECT_GT(count_colour({14, 127, 255}), 50);

  const auto other = write_run("other", 0.0, false);
  try {
    plot_compare({single_run_group(random), single_run_group(other)}, "coverage_fraction_visited",
                 png);
    FAIL() << "a run without the metric must be an error";
  } catch (const indrive::IoError& error) {
    EXPECT_NE(std::string(error.what()).find("other"), std::string::npos) << error.what();
  }
}

TEST(MeanBand, AveragesRunsInterpolatedOverTheirCommonRange) {
  // Run a: y = x on 0..10 at every 2; run b: y = 2x on 1..9 at odd x, given out of order.
  const MeanBand band = mean_band(
      {{{0, 2, 4, 6, 8, 10}, {0, 2, 4, 6, 8, 10}}, {{9, 1, 3, 5, 7}, {18, 2, 6, 10, 14}}}, 5);
  ASSERT_EQ(band.x, (std::vector<double>{1, 3, 5, 7, 9}));
  for (std::size_t i = 0; i < band.x.size(); ++i) {
    const double x = band.x[i];
    EXPECT_DOUBLE_EQ(band.mean[i], 1.5 * x);
    EXPECT_DOUBLE_EQ(band.low[i], x);
    EXPECT_DOUBLE_EQ(band.high[i], 2 * x);
  }
  // Runs that do not overlap, or have no finite point, cannot be averaged.
  EXPECT_THROW(mean_band({{{0, 1}, {0, 1}}, {{2, 3}, {0, 1}}}), std::invalid_argument);
  EXPECT_THROW(mean_band({{{0, 1}, {NAN, NAN}}}), std::invalid_argument);
}

TEST(CompareGroup, ParsesLabelAndRunsAndSaysTheFormOtherwise) {
  const CompareGroup group = parse_compare_group("disag=runs/s0/disag,runs/s1/disag");
  EXPECT_EQ(group.label, "disag");
  EXPECT_EQ(group.runs, (std::vector<std::filesystem::path>{"runs/s0/disag", "runs/s1/disag"}));
  for (const char* bad : {"runs/s0", "=runs/s0", "disag=", "disag=a,,b"}) {
    try {
      parse_compare_group(bad);
      ADD_FAILURE() << bad << " must be rejected";
    } catch (const std::invalid_argument& error) {
      EXPECT_NE(std::string(error.what()).find("LABEL=RUN"), std::string::npos) << error.what();
    }
  }
  EXPECT_EQ(single_run_group("runs/x/disag/").label, "disag");
}

TEST(PlotCompare, DrawsAGroupAsItsMeanWithABandBetweenItsRuns) {
  testing::TempDir dir;
  const auto write_run = [&](const std::string& name, double slope) {
    const auto run = dir.path() / name;
    std::filesystem::create_directories(run);
    std::ofstream out(run / "metrics.jsonl");
    for (int i = 0; i < 10; ++i) {
      out << "{\"env_steps\": " << i * 1000 << ", \"coverage\": " << slope * i << "}\n";
    }
    return run;
  };
  const auto low = write_run("s0", 0.01), high = write_run("s1", 0.05);
  const auto png = dir.path() / "group.png";
  const auto ends = plot_compare({CompareGroup{"disag", {low, high}}}, "coverage", png);
  ASSERT_EQ(ends.size(), 1u);
  EXPECT_EQ(ends[0].label, "disag (mean of 2, band min-max)");
  EXPECT_DOUBLE_EQ(ends[0].x, 9000);
  EXPECT_NEAR(ends[0].y, 0.27, 1e-12);
  EXPECT_NEAR(ends[0].low, 0.09, 1e-12);
  EXPECT_NEAR(ends[0].high, 0.45, 1e-12);
  const cv::Mat image = cv::imread(png.string());
  ASSERT_FALSE(image.empty());
  // The mean line is drawn in the first colour; the band is a light tint of it that fills the
  // wedge between the two runs: at the right end, halfway between mean and the high run.
  int line = 0;
  for (int r = 0; r < image.rows; ++r)
    for (int c = 0; c < image.cols; ++c)
      line += image.at<cv::Vec3b>(r, c) == cv::Vec3b(180, 119, 31);
  EXPECT_GT(line, 50);
  // Axes: x 0..9,000 over columns 80..780; y 0..0.45 (the band's extremes) plus 5% padding
  // over rows 425..40. At x = 5,000 the runs are at 0.05 and 0.25 and their mean at 0.15.
  const double y_min = -0.0225, y_max = 0.4725;
  const auto row_of = [&](double y) {
    return int(std::lround(425 - (y - y_min) / (y_max - y_min) * (425 - 40)));
  };
  const int column = int(std::lround(80 + 700 * 5000.0 / 9000.0));
  const cv::Vec3b inside = image.at<cv::Vec3b>(row_of(0.2), column);    // mean to high run
  const cv::Vec3b outside = image.at<cv::Vec3b>(row_of(0.35), column);  // above the band
  EXPECT_EQ(outside, cv::Vec3b(255, 255, 255));
  EXPECT_NE(inside, cv::Vec3b(255, 255, 255));
  EXPECT_GT(inside[0], inside[2]) << "the band is tinted with the series' (blue) colour";

  EXPECT_THROW(plot_compare({CompareGroup{"empty", {}}}, "coverage", png), std::invalid_argument);
}

// Rows of a learning curve in the evaluator's column order (actor/evaluator.h).
std::string curve_row(int env_steps, const std::string& town, int success, double completion) {
  std::ostringstream row;
  row << env_steps << ",3,disag,zero_shot,lane_following," << town << ",straight,10,1,2,0,"
      << success << "," << (success ? "" : "collision+lane_invasion") << ",120," << completion
      << ",0.5\n";
  return row.str();
}
const char* kCurveHeader =
    "env_steps,policy_version,method,eval_kind,task,town,route,density,traffic_seed,spawn_seed,"
    "episode,success,failure_reason,steps,route_completion,episode_return\n";

TEST(EvalCurves, PoolEvaluatorsPerTownAndSnapshotAndPlotSuccessAndCompletion) {
  testing::TempDir dir;
  const auto run = dir.path() / "run";
  std::filesystem::create_directories(run / "eval");
  {
    std::ofstream a(run / "eval" / "curve-0.csv");
    a << kCurveHeader << curve_row(1000, "town01", 1, 1.0) << curve_row(1000, "town01", 0, 0.2)
      << curve_row(2000, "town01", 1, 1.0) << curve_row(1000, "town02", 0, 0.4);
    std::ofstream b(run / "eval" / "curve-1.csv");
    b << kCurveHeader << curve_row(1000, "town01", 1, 0.9) << "2000,3,disag,zero";  // cut
    std::ofstream(run / "eval" / "town01.csv") << "not,a,curve\n";  // episode rows: ignored
  }
  const EvalCurves curves =
      read_eval_curves({run / "eval" / "curve-0.csv", run / "eval" / "curve-1.csv"});
  ASSERT_EQ(curves.size(), 2u);
  const auto& town01 = curves.at("town01");
  ASSERT_EQ(town01.size(), 2u);
  EXPECT_EQ(town01[0].env_steps, 1000);
  EXPECT_EQ(town01[0].episodes, 3);
  EXPECT_DOUBLE_EQ(town01[0].success_rate, 2.0 / 3.0);
  EXPECT_NEAR(town01[0].route_completion, (1.0 + 0.2 + 0.9) / 3.0, 1e-9);
  EXPECT_EQ(town01[1].episodes, 1);
  EXPECT_DOUBLE_EQ(town01[1].success_rate, 1.0);
  EXPECT_EQ(curves.at("town02")[0].episodes, 1);
  EXPECT_DOUBLE_EQ(curves.at("town02")[0].success_rate, 0.0);

  const auto files = plot_eval_curves(run, run / "plots");
  ASSERT_EQ(files.size(), 2u);
  for (const auto& file : files) EXPECT_FALSE(cv::imread(file.string()).empty()) << file;
  // A run without learning curves draws none.
  EXPECT_TRUE(plot_eval_curves(dir.path() / "other", dir.path() / "plots").empty());
}

TEST(EvalCurves, AMalformedRowOrAMissingColumnIsAnErrorNamingTheFile) {
  testing::TempDir dir;
  const auto bad_row = dir.path() / "curve-0.csv";
  std::ofstream(bad_row) << kCurveHeader << "x" << curve_row(1000, "town01", 1, 1.0)
                         << curve_row(2000, "town01", 1, 1.0);
  try {
    read_eval_curves({bad_row});
    FAIL() << "a non-numeric env_steps must be an error";
  } catch (const indrive::IoError& error) {
    EXPECT_NE(std::string(error.what()).find("curve-0.csv:2"), std::string::npos) << error.what();
  }
  const auto no_column = dir.path() / "curve-1.csv";
  std::ofstream(no_column) << "env_steps,town\n1000,town01\n";
  try {
    read_eval_curves({no_column});
    FAIL() << "a file without a success column must be an error";
  } catch (const indrive::IoError& error) {
    EXPECT_NE(std::string(error.what()).find("'success'"), std::string::npos) << error.what();
  }
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
