// `indrive dashboard`: one self-contained HTML page for one run or several.
//
// The page opens from file:// with no server and no network: Chart.js (Debian's libjs-chart.js,
// embedded into the program at build time) and the data are inlined, the pictures are data
// URIs, and only the evaluation videos stay beside the page (transcoded to WebM under
// <page folder>/media/, since browsers do not play the MPEG-4 part 2 files the project writes).
//
//   DashboardInput input{.runs = {single_run_group("runs/smoke")}};
//   const DashboardStats stats = write_dashboard(input, "runs/smoke/index.html");
//
// What it shows, per run (or per group of runs, as mean and min-max band):
//   curves grouped by what they measure (world model, intrinsic module, behaviour, exploration,
//   throughput and pacing, dropped messages by reason, evaluation SR and route completion over
//   env steps), with hover values and drag-to-zoom; the report's tables over the runs'
//   evaluation CSVs (the layout bound row on the route set of the runs' env.route_set, none
//   when they differ); the coverage map and town maps found in <run>/plots/; the videos of
//   <run>/videos/; the resolved config.yaml; the processes' last states (<run>/status.json,
//   written by `indrive launch`).
#pragma once

#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "indrive/deploy/plot.h"

namespace indrive::deploy {

struct DashboardInput {
  // Each group is one legend entry: a single run as its own line, several runs (the seeds of
  // one method) as their mean with a band from the lowest to the highest.
  std::vector<CompareGroup> runs;
  std::string title;  // empty: made from the run labels
  // > 0: the page reloads itself every this many seconds and says that the run is live.
  double live_refresh_s = 0.0;
  // Shown in the header when the run has ended, e.g. "ended 2026-12-03 01:02:03, learner
  // exit code 0"; empty and not live: the page says when it was written.
  std::string ended;
  // The evaluation videos above the curves (indrive dashboard --videos-first): for a page whose
  // point is a policy driving, as the main job's.
  bool videos_first = false;
  std::string seen_town = "town01";  // the report's generalisation-gap columns
  std::string heldout_town = "town02";
};

struct DashboardStats {
  std::filesystem::path page;
  std::size_t bytes = 0;
  double seconds = 0.0;      // wall time of the whole write
  std::size_t charts = 0;    // charts on the page
  std::size_t points = 0;    // data points over all charts (bands not counted)
  std::size_t videos = 0;    // videos shown
  std::size_t pictures = 0;  // coverage and town maps shown
};

// What a page writer keeps between writes of the same runs' page (indrive launch, indrive
// dashboard --watch): each write then parses only the metrics lines appended since the last.
class DashboardCache {
 public:
  // The columns of a metrics.jsonl as they are now (a copy: the charts take them apart).
  MetricColumns metrics(const std::filesystem::path& metrics_jsonl);

 private:
  std::map<std::filesystem::path, MetricsFollower> followers_;
};

// The charts' groups, in page order, and the group a metrics.jsonl key belongs to.
const std::vector<std::string>& dashboard_chart_groups();
std::string dashboard_chart_group(const std::string& metric);

// Renders the page. `media_dir` is where transcoded videos go and `page_dir` the folder the page
// will live in (video links are relative to it). Throws IoError naming the run when one of them
// has none of metrics.jsonl, eval/ or config.yaml, or when a file is malformed.
// `cache`: as above; null: every file is read whole.
std::string render_dashboard(const DashboardInput& input, const std::filesystem::path& page_dir,
                             DashboardStats* stats = nullptr, DashboardCache* cache = nullptr);

// Renders and writes the page atomically (a reader never sees half a page).
DashboardStats write_dashboard(const DashboardInput& input, const std::filesystem::path& page,
                               DashboardCache* cache = nullptr);

// "YYYY-MM-DD HH:MM:SS", local time: the stamps of the page and of <run>/status.json.
std::string local_time_now();

// Chart.js as shipped by libjs-chart.js, embedded at build time.
std::string_view chartjs_source();
// The page's own style and script (deploy/assets/dashboard.css and .js), embedded likewise.
std::string_view dashboard_style();
std::string_view dashboard_script();

}  // namespace indrive::deploy
