// The dashboard page's content: which charts it has and the data behind them, the tables,
// pictures, videos, config and process states, the live and ended states, and the errors for
// what is not a run. What a browser makes of the page: dashboard_browser_test.
#include "indrive/deploy/dashboard.h"

#include <gtest/gtest.h>

#include <fstream>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include "child_process.h"
#include "indrive/basics/episode_csv.h"
#include "indrive/basics/run_dir.h"
#include "indrive/envserver/video.h"
#include "testing.h"

namespace indrive::deploy {
namespace {

namespace fs = std::filesystem;

// A run directory with `lines` metrics lines (a dropped-message reason among them), a config, a
// learning-curve CSV, a status file, a coverage-map PNG and a video.
fs::path write_run(const fs::path& dir, int lines, double slope) {
  fs::create_directories(dir / "eval");
  fs::create_directories(dir / "plots");
  {
    std::ofstream out(dir / "metrics.jsonl");
    for (int i = 1; i <= lines; ++i) {
      out << "{\"env_steps\":" << i * 100 << ",\"time\":1.0,\"wm/recon\":" << 100.0 - slope * i
          << ",\"intrinsic/raw_reward\":" << slope * 1e-4 * i << ",\"dropped_wrong_run\":" << i / 3
          << ",\"dropped_bad_checksum\":0,\"random_policy\":false";
      // A key that only every other line has (as evaluation figures are).
      if (i % 2 == 0) out << ",\"expl/entropy\":" << 2.0 - 0.001 * i;
      out << "}\n";
    }
  }
  std::ofstream(dir / "config.yaml") << "preset: tiny\nenv:\n  town: town01  # <not html>\n";
  std::ofstream(dir / "eval" / "curve-0.csv")
      << "env_steps,policy_version,method,eval_kind,task,town,route,density,traffic_seed,"
         "spawn_seed,episode,success,failure_reason,steps,route_completion,episode_return\n"
      << "1000,10,disag,zero_shot,exploration,town02,straight,5,1,2,0,1,,80,1.0,0\n"
      << "1000,10,disag,zero_shot,exploration,town02,straight,5,1,2,1,0,collision,30,0.5,0\n"
      << "2000,20,disag,zero_shot,exploration,town02,straight,5,1,2,0,1,,80,1.0,0\n";
  std::ofstream(dir / "eval" / "evaluator-0.csv")
      << episode_csv_header_v1() << "\n"  // a file of an older build: read as strict
      << "run,disag,zero_shot,exploration,0,7,town02,straight,5,101,11,0,1,,59,1.0,0\n"
      << "run,disag,zero_shot,exploration,0,7,town02,straight,5,101,12,1,0,lane_invasion,40,0.3,"
         "0\n";
  std::ofstream(dir / "train-episodes.csv")
      << episode_csv_header_v1() << "\n"  // a file of an older build: read as strict
      << "run,disag,training,lane_following,0,3,town01,straight,10,5,6,0,1,,250,1.0,240.5\n"
      << "run,disag,training,lane_following,0,4,town01,right_loop,10,5,6,1,0,off_route,90,0.2,"
         "30.5\n";
  std::ofstream(dir / "status.json")
      << R"({"written":"2026-12-03 01:00:00","state":"ended","processes":[)"
      << R"({"name":"learner","state":"exited","pid":12,"restarts":1,"last_exit_code":0,)"
      << R"("last_line":"steps 100 <done>"}]})";
  cv::imwrite((dir / "plots" / "coverage_map.png").string(),
              cv::Mat(20, 30, CV_8UC3, cv::Scalar(0, 128, 255)));
  cv::imwrite((dir / "plots" / "wm_recon.png").string(), cv::Mat(4, 4, CV_8UC3));
  {
    fs::create_directories(dir / "videos");
    env::VideoWriter video(dir / "videos" / "eval-town02-straight.mp4", cv::Size(64, 48), 10.0);
    for (int f = 0; f < 5; ++f) video.write(cv::Mat(48, 64, CV_8UC3, cv::Scalar(f * 40, 0, 0)));
  }
  return dir;
}

// The DATA object the page's script draws from.
nlohmann::json page_data(const std::string& html) {
  const std::string marker = "const DATA = ";
  const auto from = html.find(marker);
  EXPECT_NE(from, std::string::npos);
  const auto to = html.find(";\n", from);
  return nlohmann::json::parse(html.substr(from + marker.size(), to - from - marker.size()));
}

const nlohmann::json* find_chart(const nlohmann::json& data, const std::string& title) {
  for (const auto& chart : data["charts"]) {
    if (chart["title"] == title) return &chart;
  }
  return nullptr;
}

std::size_t non_null(const nlohmann::json& values) {
  std::size_t n = 0;
  for (const auto& v : values) n += !v.is_null();
  return n;
}

TEST(DashboardGroups, KeysGoToTheGroupOfWhatTheyMeasure) {
  EXPECT_EQ(dashboard_chart_group("wm/kl"), "world model");
  EXPECT_EQ(dashboard_chart_group("intrinsic/raw_reward"), "intrinsic module");
  EXPECT_EQ(dashboard_chart_group("expl/entropy"), "behaviour");
  EXPECT_EQ(dashboard_chart_group("task/reward"), "behaviour");
  EXPECT_EQ(dashboard_chart_group("episode_length_last20"), "exploration");
  EXPECT_EQ(dashboard_chart_group("coverage_fraction_visited"), "exploration");
  EXPECT_EQ(dashboard_chart_group("updates_per_s"), "throughput and pacing");
  EXPECT_EQ(dashboard_chart_group("time/update_s"), "throughput and pacing");
  EXPECT_EQ(dashboard_chart_group("policy_lag"), "throughput and pacing");
  EXPECT_EQ(dashboard_chart_group("dropped_bad_shape"), "dropped messages");
  EXPECT_EQ(dashboard_chart_group("something_new"), "other");
  for (const auto& key : {"wm/kl", "dropped_x", "something_new", "expl/entropy"}) {
    const auto& groups = dashboard_chart_groups();
    EXPECT_NE(std::find(groups.begin(), groups.end(), dashboard_chart_group(key)), groups.end());
  }
}

TEST(Dashboard, OneRunsPageHoldsEveryMetricLineTablesMapsVideoConfigAndProcesses) {
  testing::TempDir dir;
  const fs::path run = write_run(dir.path() / "run", 40, 1.0);
  const DashboardStats stats =
      write_dashboard({.runs = {single_run_group(run)}}, run / "index.html");
  const std::string html = testing::slurp(run / "index.html");
  EXPECT_EQ(stats.bytes, html.size());
  EXPECT_EQ(stats.pictures, 1u);  // the coverage map, not the metric PNG
  EXPECT_EQ(stats.videos, 1u);

  const auto data = page_data(html);
  const auto* recon = find_chart(data, "wm/recon");
  ASSERT_NE(recon, nullptr);
  EXPECT_EQ((*recon)["group"], "world model");
  ASSERT_EQ((*recon)["series"].size(), 1u);
  EXPECT_EQ(non_null((*recon)["series"][0]["y"]), 40u);  // one point per metrics line
  EXPECT_DOUBLE_EQ((*recon)["series"][0]["y"][39].get<double>(), 60.0);
  const auto* entropy = find_chart(data, "expl/entropy");
  ASSERT_NE(entropy, nullptr);
  EXPECT_EQ(non_null((*entropy)["series"][0]["y"]), 20u);  // the lines that have it
  // x arrays are shared: wm/recon's is the run's 40 steps.
  const auto& xs = data["xs"][(*recon)["series"][0]["xi"].get<int>()];
  ASSERT_EQ(xs.size(), 40u);
  EXPECT_DOUBLE_EQ(xs[39].get<double>(), 4000.0);
  // Neither the time stamp nor the boolean is a chart.
  EXPECT_EQ(find_chart(data, "time"), nullptr);
  EXPECT_EQ(find_chart(data, "random_policy"), nullptr);
  // Dropped messages: one chart, a line per reason.
  const auto* dropped = find_chart(data, "dropped messages by reason");
  ASSERT_NE(dropped, nullptr);
  ASSERT_EQ((*dropped)["series"].size(), 2u);
  EXPECT_EQ((*dropped)["series"][0]["label"], "run: bad_checksum");
  EXPECT_EQ((*dropped)["series"][1]["label"], "run: wrong_run");
  EXPECT_NE((*dropped)["series"][0]["colour"], (*dropped)["series"][1]["colour"]);
  // The continuous evaluator's curve: SR per env-step count, pooled over episodes.
  const auto* sr = find_chart(data, "success rate (continuous evaluator)");
  ASSERT_NE(sr, nullptr);
  EXPECT_EQ((*sr)["series"][0]["label"], "run town02");
  EXPECT_DOUBLE_EQ((*sr)["series"][0]["y"][0].get<double>(), 50.0);
  EXPECT_DOUBLE_EQ((*sr)["series"][0]["y"][1].get<double>(), 100.0);
  // Evaluation comes first on the page.
  EXPECT_EQ(data["charts"][0]["group"], "evaluation");
  EXPECT_EQ(stats.charts, data["charts"].size());

  // The report's tables, from the evaluator's episodes: SR 50 on town02's straight.
  EXPECT_NE(html.find("<th>straight SR</th>"), std::string::npos);
  EXPECT_NE(html.find("<td>50.0 ["), std::string::npos);
  EXPECT_NE(html.find("<th>lane_invasion</th>"), std::string::npos);
  // Training per route, from train-episodes.csv.
  EXPECT_NE(html.find("<h2>Training per route</h2>"), std::string::npos);
  EXPECT_NE(html.find("<td>right_loop</td><td>1</td><td>0%</td><td>20%</td><td>30.5</td>"),
            std::string::npos)
      << html.substr(html.find("Training per route"), 1500);
  // Coverage map as a data URI, the video as a WebM beside the page.
  EXPECT_NE(html.find("src=\"data:image/png;base64,"), std::string::npos);
  EXPECT_NE(html.find("src=\"media/run-eval-town02-straight.webm\""), std::string::npos);
  EXPECT_GT(fs::file_size(run / "media" / "run-eval-town02-straight.webm"), 0u);
  // Config and process states, escaped.
  EXPECT_NE(html.find("town: town01  # &lt;not html&gt;"), std::string::npos);
  EXPECT_NE(html.find("steps 100 &lt;done&gt;"), std::string::npos);
  EXPECT_EQ(html.find("<done>"), std::string::npos);
  // Self-contained: Chart.js inlined, nothing fetched.
  EXPECT_NE(html.find("Chart.js v"), std::string::npos);
  EXPECT_EQ(html.find("<script src="), std::string::npos);
  EXPECT_EQ(html.find("http-equiv=\"refresh\""), std::string::npos);
  EXPECT_NE(html.find("ended 2026-12-03 01:00:00"), std::string::npos);  // from status.json
  // Videos come after the curves, unless the page is about a policy driving.
  EXPECT_LT(html.find("<section id=\"curves\">"), html.find("<section id=\"videos\">"));
  const std::string videos_first =
      render_dashboard({.runs = {single_run_group(run)}, .videos_first = true}, run);
  EXPECT_LT(videos_first.find("<section id=\"videos\">"),
            videos_first.find("<section id=\"curves\">"));
  EXPECT_NE(videos_first.find("src=\"media/run-eval-town02-straight.webm\""), std::string::npos);
  EXPECT_EQ(videos_first.find("<section id=\"videos\">"),
            videos_first.rfind("<section id=\"videos\">"))
      << "one videos section";
}

TEST(Dashboard, LiveAndEndedPagesSaySo) {
  testing::TempDir dir;
  const fs::path run = write_run(dir.path() / "run", 5, 1.0);
  fs::remove(run / "status.json");
  DashboardInput input{.runs = {single_run_group(run)}, .live_refresh_s = 30.0};
  std::string html = render_dashboard(input, run);
  EXPECT_NE(html.find("<meta http-equiv=\"refresh\" content=\"30\">"), std::string::npos);
  EXPECT_NE(html.find(">live<"), std::string::npos);
  input.live_refresh_s = 0.0;
  input.ended = "ended 2026-12-03 02:00:00, learner exit code 0";
  html = render_dashboard(input, run);
  EXPECT_EQ(html.find("http-equiv=\"refresh\""), std::string::npos);
  EXPECT_NE(html.find("ended 2026-12-03 02:00:00, learner exit code 0"), std::string::npos);
}

TEST(Dashboard, SeveralRunsAreOverlaidAndSeedGroupsAreAMeanWithABand) {
  testing::TempDir dir;
  const fs::path a = write_run(dir.path() / "s0", 10, 1.0);
  const fs::path b = write_run(dir.path() / "s1", 10, 3.0);
  const fs::path other = write_run(dir.path() / "random", 10, 2.0);
  DashboardInput input{.runs = {{"disag", {a, b}}, single_run_group(other)}};
  const std::string html = render_dashboard(input, dir.path());
  const auto data = page_data(html);
  const auto* recon = find_chart(data, "wm/recon");
  ASSERT_NE(recon, nullptr);
  ASSERT_EQ((*recon)["series"].size(), 2u);
  const auto& group = (*recon)["series"][0];
  EXPECT_EQ(group["label"], "disag (mean of 2, band min-max)");
  // At the last step the two seeds are at 100 - 10 = 90 and 100 - 30 = 70.
  const auto last = group["y"].size() - 1;
  EXPECT_DOUBLE_EQ(group["y"][last].get<double>(), 80.0);
  EXPECT_DOUBLE_EQ(group["low"][last].get<double>(), 70.0);
  EXPECT_DOUBLE_EQ(group["high"][last].get<double>(), 90.0);
  EXPECT_EQ((*recon)["series"][1]["label"], "random");
  EXPECT_FALSE((*recon)["series"][1].contains("low"));
  EXPECT_NE((*recon)["series"][0]["colour"], (*recon)["series"][1]["colour"]);
  // Every run's video, named by its run.
  for (const auto* name : {"s0-eval", "s1-eval", "random-eval"}) {
    EXPECT_NE(html.find(std::string("media/") + name), std::string::npos) << name;
  }
}

TEST(Dashboard, ALabelThatWouldCloseTheScriptStaysData) {
  testing::TempDir dir;
  const fs::path run = write_run(dir.path() / "run", 3, 1.0);
  const std::string html = render_dashboard({.runs = {{"x</script><b>", {run}}}}, dir.path());
  const auto data = page_data(html);
  EXPECT_EQ(find_chart(data, "wm/recon")->at("series")[0]["label"], "x</script><b>");
  EXPECT_EQ(html.find("x</script>"), std::string::npos);
}

TEST(Dashboard, WhatIsNotARunIsAnErrorThatSaysWhatARunIs) {
  testing::TempDir dir;
  fs::create_directories(dir.path() / "empty");
  const std::string message = testing::error_of<IoError>(
      [&] { render_dashboard({.runs = {single_run_group(dir.path() / "empty")}}, dir.path()); });
  EXPECT_NE(message.find("empty has no metrics.jsonl, eval/ or config.yaml"), std::string::npos)
      << message;
  EXPECT_NE(message.find("run directory"), std::string::npos) << message;

  // A corrupt line inside metrics.jsonl names the file and the line.
  const fs::path run = write_run(dir.path() / "bad", 5, 1.0);
  {
    std::ofstream out(run / "metrics.jsonl", std::ios::app);
    out << "{not json\n{\"env_steps\": 700}\n";
  }
  const std::string corrupt = testing::error_of<IoError>(
      [&] { render_dashboard({.runs = {single_run_group(run)}}, dir.path()); });
  EXPECT_NE(corrupt.find("metrics.jsonl:6: not JSON"), std::string::npos) << corrupt;
}

TEST(Dashboard, TheLayoutBoundIsTakenFromTheRouteSetTheRunsRanWith) {
  testing::TempDir dir;
  const fs::path right = write_run(dir.path() / "right", 4, 1.0);  // no env.route_set: right
  const fs::path left = write_run(dir.path() / "left", 4, 1.0);
  std::ofstream(left / "config.yaml") << "env:\n  town: town01\n  route_set: left\n";
  const auto page = [&](std::vector<fs::path> runs) {
    return render_dashboard({.runs = {{.label = "runs", .runs = std::move(runs)}}}, dir.path());
  };
  EXPECT_NE(page({right}).find("route set `right`"), std::string::npos);
  EXPECT_NE(page({left}).find("route set `left`"), std::string::npos);
  // Runs on different sets: no one bound describes the tables, so there is no such row.
  const std::string mixed = page({right, left});
  EXPECT_NE(mixed.find("<th>straight SR</th>"), std::string::npos);
  EXPECT_EQ(mixed.find("layout bound"), std::string::npos);
}

TEST(Dashboard, ARunWithOnlyAConfigStillGetsAPage) {
  testing::TempDir dir;
  fs::create_directories(dir.path() / "new");
  std::ofstream(dir.path() / "new" / "config.yaml") << "preset: tiny\n";
  const std::string html =
      render_dashboard({.runs = {single_run_group(dir.path() / "new")}}, dir.path());
  EXPECT_NE(html.find("no metrics yet"), std::string::npos);
  EXPECT_NE(html.find("no evaluation episodes yet"), std::string::npos);
  EXPECT_NE(html.find("preset: tiny"), std::string::npos);
}

}  // namespace
}  // namespace indrive::deploy
