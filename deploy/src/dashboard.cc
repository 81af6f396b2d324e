#include "indrive/deploy/dashboard.h"

#include <fcntl.h>
#include <unistd.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <charconv>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <opencv2/videoio.hpp>
#include <set>
#include <sstream>

#include "indrive/basics/episode_csv.h"
#include "indrive/basics/log.h"
#include "indrive/basics/run_dir.h"
#include "indrive/deploy/report.h"
#include "indrive/deploy/training_episodes.h"
#include "indrive/envserver/town.h"

namespace indrive::deploy {
namespace fs = std::filesystem;
namespace {

// Videos transcoded and shown per run; the rest are named with their folder.
constexpr std::size_t kMaxVideosPerRun = 12;

std::string escape_html(std::string_view text) {
  std::string out;
  out.reserve(text.size());
  for (const char c : text) {
    switch (c) {
      case '&':
        out += "&amp;";
        break;
      case '<':
        out += "&lt;";
        break;
      case '>':
        out += "&gt;";
        break;
      case '"':
        out += "&quot;";
        break;
      default:
        out += c;
    }
  }
  return out;
}

std::string read_text(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw IoError("cannot open " + path.string());
  std::ostringstream text;
  text << in.rdbuf();
  return text.str();
}

std::string base64(std::string_view bytes) {
  static constexpr char kDigits[] =
      "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  out.reserve((bytes.size() + 2) / 3 * 4);
  std::size_t i = 0;
  for (; i + 2 < bytes.size(); i += 3) {
    const unsigned v = static_cast<unsigned char>(bytes[i]) << 16 |
                       static_cast<unsigned char>(bytes[i + 1]) << 8 |
                       static_cast<unsigned char>(bytes[i + 2]);
    for (int k = 18; k >= 0; k -= 6) out += kDigits[(v >> k) & 63];
  }
  if (i < bytes.size()) {
    unsigned v = static_cast<unsigned char>(bytes[i]) << 16;
    if (i + 1 < bytes.size()) v |= static_cast<unsigned char>(bytes[i + 1]) << 8;
    out += kDigits[(v >> 18) & 63];
    out += kDigits[(v >> 12) & 63];
    out += i + 1 < bytes.size() ? kDigits[(v >> 6) & 63] : '=';
    out += '=';
  }
  return out;
}

// Six significant digits: what a reader can tell apart on a chart, and half the bytes of
// full precision on a 10,000-line run.
void append_number(std::string& out, double value) {
  if (!std::isfinite(value)) {
    out += "null";
    return;
  }
  char buffer[32];
  const auto result =
      std::to_chars(buffer, buffer + sizeof(buffer), value, std::chars_format::general, 6);
  out.append(buffer, result.ptr);
}

void append_numbers(std::string& out, const std::vector<double>& values) {
  out += '[';
  for (std::size_t i = 0; i < values.size(); ++i) {
    if (i > 0) out += ',';
    append_number(out, values[i]);
  }
  out += ']';
}

// The markdown of render_markdown (headings, paragraphs, pipe tables) as HTML.
std::string markdown_to_html(const std::string& markdown) {
  std::ostringstream html;
  std::istringstream lines(markdown);
  bool in_table = false;
  bool header_row = false;
  const auto cells = [](const std::string& line) {
    std::vector<std::string> out;
    std::string cell;
    for (std::size_t i = 1; i < line.size(); ++i) {
      if (line[i] == '|') {
        out.push_back(cell);
        cell.clear();
      } else {
        cell += line[i];
      }
    }
    for (auto& c : out) {
      c.erase(0, c.find_first_not_of(' '));
      c.erase(c.find_last_not_of(' ') + 1);
    }
    return out;
  };
  for (std::string line; std::getline(lines, line);) {
    const bool table_line = line.starts_with("|");
    if (in_table && !table_line) {
      html << "</table>\n";
      in_table = false;
    }
    if (table_line) {
      if (!in_table) {
        html << "<table>\n";
        in_table = true;
        header_row = true;
      }
      const auto row = cells(line);
      if (!row.empty() && row[0].starts_with("---")) continue;  // the separator line
      html << "<tr>";
      for (const auto& cell : row) {
        html << (header_row ? "<th>" : "<td>") << escape_html(cell)
             << (header_row ? "</th>" : "</td>");
      }
      html << "</tr>\n";
      header_row = false;
    } else if (line.starts_with("### ")) {
      html << "<h4>" << escape_html(line.substr(4)) << "</h4>\n";
    } else if (line.starts_with("## ")) {
      html << "<h3>" << escape_html(line.substr(3)) << "</h3>\n";
    } else if (line.starts_with("# ")) {
      continue;  // the page has its own section title
    } else if (!line.empty()) {
      html << "<p>" << escape_html(line) << "</p>\n";
    }
  }
  if (in_table) html << "</table>\n";
  return html.str();
}

struct Series {
  std::string label;
  int colour = 0;
  std::vector<double> x, y, low, high;  // low/high empty: no band
};

struct Chart {
  std::string group;
  std::string title;
  std::string y_label;
  std::vector<Series> series;
};

// Data points of one series that a chart draws (NaN and infinity are gaps).
std::size_t finite_points(const Series& s) {
  std::size_t n = 0;
  for (std::size_t i = 0; i < s.y.size(); ++i) n += std::isfinite(s.x[i]) && std::isfinite(s.y[i]);
  return n;
}

// Every chart of the page, from the groups' metrics.jsonl files and evaluation curves.
std::vector<Chart> build_charts(const std::vector<CompareGroup>& groups, DashboardCache* cache) {
  std::map<std::pair<std::string, std::string>, Chart> charts;  // (group, title) -> chart
  const auto chart = [&](const std::string& group, const std::string& title,
                         const std::string& y_label) -> Chart& {
    Chart& c = charts[{group, title}];
    c.group = group;
    c.title = title;
    c.y_label = y_label;
    return c;
  };
  for (std::size_t g = 0; g < groups.size(); ++g) {
    const CompareGroup& group = groups[g];
    const int colour = static_cast<int>(g);
    // key -> one (x, y) per run of the group that logs it
    std::map<std::string, std::vector<std::pair<std::vector<double>, std::vector<double>>>> keys;
    std::vector<fs::path> curve_files;
    for (const auto& run : group.runs) {
      if (fs::exists(run / "metrics.jsonl")) {
        MetricColumns columns = cache != nullptr ? cache->metrics(run / "metrics.jsonl")
                                                 : read_metric_columns(run / "metrics.jsonl");
        for (auto& [key, xy] : columns) {
          keys[key].push_back(std::move(xy));
        }
      }
      for (auto& file : run_files(run / "eval", "curve-", ".csv")) {
        curve_files.push_back(std::move(file));
      }
    }
    for (auto& [key, runs] : keys) {
      const std::string group_name = dashboard_chart_group(key);
      const bool dropped = key.starts_with("dropped_");
      // Dropped messages: one chart, a line per reason (and run).
      Chart& c = dropped ? chart(group_name, "dropped messages by reason", "messages (cumulative)")
                         : chart(group_name, key, "");
      const std::string reason = dropped ? key.substr(std::string("dropped_").size()) : "";
      const std::string label = dropped ? group.label + ": " + reason : group.label;
      const int series_colour =
          dropped ? static_cast<int>(c.series.size()) : colour;  // reasons need their own colours
      if (runs.size() == 1) {
        c.series.push_back(
            {label, series_colour, std::move(runs[0].first), std::move(runs[0].second), {}, {}});
        continue;
      }
      try {
        MeanBand band = mean_band(runs);
        c.series.push_back({label + " (mean of " + std::to_string(runs.size()) + ", band min-max)",
                            series_colour, std::move(band.x), std::move(band.mean),
                            std::move(band.low), std::move(band.high)});
      } catch (const std::invalid_argument& error) {
        INDRIVE_LOG(kWarn, "dashboard") << group.label << ", " << key << ": " << error.what()
                                        << "; its runs are not drawn as one band";
      }
    }
    const EvalCurves curves = read_eval_curves(curve_files);
    for (const auto& [town, points] : curves) {
      Series sr{group.label + " " + town, colour, {}, {}, {}, {}};
      Series rc = sr;
      for (const auto& p : points) {
        sr.x.push_back(p.env_steps);
        sr.y.push_back(100.0 * p.success_rate);
        rc.x.push_back(p.env_steps);
        rc.y.push_back(100.0 * p.route_completion);
      }
      chart("evaluation", "success rate (continuous evaluator)", "SR %")
          .series.push_back(std::move(sr));
      chart("evaluation", "route completion (continuous evaluator)", "mean route completion %")
          .series.push_back(std::move(rc));
    }
  }
  // Two towns of one group share its colour: give each series of a chart its own where a
  // chart has more series than groups.
  std::vector<Chart> ordered;
  for (const auto& name : dashboard_chart_groups()) {
    for (auto& [key, c] : charts) {
      if (key.first != name) continue;
      if (c.group == "evaluation") {
        for (std::size_t i = 0; i < c.series.size(); ++i) c.series[i].colour = static_cast<int>(i);
      }
      ordered.push_back(std::move(c));
    }
  }
  return ordered;
}

// The charts as one JSON object: x arrays shared between the series that have the same one
// (every key of one metrics.jsonl usually does), so a long run's steps are written once.
std::string charts_json(const std::vector<Chart>& charts, std::size_t* points) {
  std::map<std::vector<double>, std::size_t> x_index;
  std::vector<const std::vector<double>*> xs;
  std::string body = "\"charts\":[";
  for (std::size_t c = 0; c < charts.size(); ++c) {
    const Chart& chart = charts[c];
    if (c > 0) body += ',';
    body += "{\"id\":\"chart" + std::to_string(c) +
            "\",\"group\":" + nlohmann::json(chart.group).dump() +
            ",\"title\":" + nlohmann::json(chart.title).dump() +
            ",\"y_label\":" + nlohmann::json(chart.y_label).dump() + ",\"series\":[";
    for (std::size_t s = 0; s < chart.series.size(); ++s) {
      const Series& series = chart.series[s];
      auto [it, inserted] = x_index.try_emplace(series.x, xs.size());
      if (inserted) xs.push_back(&it->first);
      if (s > 0) body += ',';
      body += "{\"label\":" + nlohmann::json(series.label).dump() +
              ",\"colour\":" + std::to_string(series.colour) +
              ",\"xi\":" + std::to_string(it->second) + ",\"y\":";
      append_numbers(body, series.y);
      if (!series.low.empty()) {
        body += ",\"low\":";
        append_numbers(body, series.low);
        body += ",\"high\":";
        append_numbers(body, series.high);
      }
      body += '}';
      if (points != nullptr) *points += finite_points(series);
    }
    body += "]}";
  }
  body += ']';
  std::string out = "{\"xs\":[";
  for (std::size_t i = 0; i < xs.size(); ++i) {
    if (i > 0) out += ',';
    append_numbers(out, *xs[i]);
  }
  out += "]," + body + "}";
  // Inside <script>, a "</" from a run's label or a metric's name would end the script: JSON
  // allows "<\/" for it.
  for (auto at = out.find("</"); at != std::string::npos; at = out.find("</", at + 3)) {
    out.replace(at, 2, "<\\/");
  }
  return out;
}

// `name.mp4` of a run as a WebM beside the page (kept while newer than its source).
std::optional<fs::path> browser_video(const fs::path& source, const fs::path& target) {
  std::error_code error;
  if (fs::exists(target) &&
      fs::last_write_time(target, error) >= fs::last_write_time(source, error)) {
    return target;
  }
  cv::VideoCapture in(source.string(), cv::CAP_FFMPEG);
  if (!in.isOpened()) {
    INDRIVE_LOG(kWarn, "dashboard")
        << "cannot read video " << source.string() << "; it is left out";
    return std::nullopt;
  }
  const double fps = in.get(cv::CAP_PROP_FPS) > 0 ? in.get(cv::CAP_PROP_FPS) : 10.0;
  const cv::Size size(static_cast<int>(in.get(cv::CAP_PROP_FRAME_WIDTH)),
                      static_cast<int>(in.get(cv::CAP_PROP_FRAME_HEIGHT)));
  fs::create_directories(target.parent_path());
  const fs::path partial = target.string() + ".partial.webm";
  // OpenCV 4.6 prints "tag 0x30385056/'VP80' is not supported with codec id 139 and format
  // 'webm / WebM'" to stderr for every WebM it opens, then uses VP8 anyway; the line reads as an
  // error in the main job's output, so stderr is closed while the writer opens (a real failure
  // is caught by isOpened() below).
  const int saved_stderr = ::dup(STDERR_FILENO);
  if (const int null_fd = ::open("/dev/null", O_WRONLY); null_fd >= 0) {
    ::dup2(null_fd, STDERR_FILENO);
    ::close(null_fd);
  }
  cv::VideoWriter out(partial.string(), cv::CAP_FFMPEG, cv::VideoWriter::fourcc('V', 'P', '8', '0'),
                      fps, size, true);
  if (saved_stderr >= 0) {
    ::dup2(saved_stderr, STDERR_FILENO);
    ::close(saved_stderr);
  }
  if (!out.isOpened()) {
    INDRIVE_LOG(kWarn, "dashboard") << "cannot write a WebM video (OpenCV's FFmpeg backend, VP8); "
                                    << source.string() << " is left out";
    return std::nullopt;
  }
  cv::Mat frame;
  while (in.read(frame)) out.write(frame);
  out.release();
  fs::rename(partial, target);
  return target;
}

std::string status_html(const fs::path& status_file) {
  nlohmann::json status;
  try {
    status = nlohmann::json::parse(read_text(status_file));
  } catch (const nlohmann::json::exception& error) {
    throw IoError(status_file.string() + " is not JSON (" + error.what() +
                  "); it is written by indrive launch");
  }
  std::ostringstream html;
  html << "<p>as of " << escape_html(status.value("written", std::string("?")));
  if (status.contains("state")) html << " (" << escape_html(status.value("state", "")) << ")";
  html << "</p>\n<table><tr><th>process</th><th>state</th><th>pid</th><th>restarts</th>"
          "<th>last exit code</th><th>last output line</th></tr>\n";
  for (const auto& p : status.value("processes", nlohmann::json::array())) {
    html << "<tr><td>" << escape_html(p.value("name", "")) << "</td><td class=\"state-"
         << escape_html(p.value("state", "")) << "\">" << escape_html(p.value("state", ""))
         << "</td><td>" << p.value("pid", -1) << "</td><td>" << p.value("restarts", 0)
         << "</td><td>" << p.value("last_exit_code", 0) << "</td><td><code>"
         << escape_html(p.value("last_line", "")) << "</code></td></tr>\n";
  }
  html << "</table>\n";
  return html.str();
}

// The built-in towns' route set the runs ran with: env.route_set of each run's resolved
// config.yaml (right, the default, where a run has none). Empty when the runs disagree or name
// a set this build does not know: then no one set's layout bound describes the tables.
std::string route_set_of(const std::vector<fs::path>& runs) {
  std::set<std::string> sets;
  for (const auto& run : runs) {
    std::string set(env::kRouteSets.front());
    const fs::path path = run / "config.yaml";
    if (fs::exists(path)) {
      try {
        const YAML::Node config = YAML::LoadFile(path.string());
        if (config["env"] && config["env"]["route_set"]) {
          set = config["env"]["route_set"].as<std::string>();
        }
      } catch (const YAML::Exception&) {
        // Not readable YAML: the page still shows it as text below; the default set.
      }
    }
    if (!env::is_route_set(set)) return "";
    sets.insert(set);
  }
  return sets.size() == 1 ? *sets.begin() : "";
}

}  // namespace

std::string local_time_now() {
  char text[32];
  const std::time_t now = std::time(nullptr);
  std::tm parts{};
  localtime_r(&now, &parts);
  std::strftime(text, sizeof(text), "%Y-%m-%d %H:%M:%S", &parts);
  return text;
}

MetricColumns DashboardCache::metrics(const fs::path& metrics_jsonl) {
  auto [it, inserted] = followers_.try_emplace(metrics_jsonl, metrics_jsonl);
  return it->second.update();
}

const std::vector<std::string>& dashboard_chart_groups() {
  static const std::vector<std::string> groups = {
      "evaluation",  "world model",           "intrinsic module", "behaviour",
      "exploration", "throughput and pacing", "dropped messages", "other"};
  return groups;
}

std::string dashboard_chart_group(const std::string& metric) {
  if (metric.starts_with("wm/")) return "world model";
  if (metric.starts_with("intrinsic/")) return "intrinsic module";
  if (metric.starts_with("expl/") || metric.starts_with("task/") ||
      metric.starts_with("episode_return") || metric.starts_with("episode_success")) {
    return "behaviour";
  }
  if (metric.starts_with("coverage_") || metric.starts_with("episode_") || metric == "episodes") {
    return "exploration";
  }
  if (metric.starts_with("dropped_")) return "dropped messages";
  if (metric.starts_with("time/") || metric.ends_with("_per_s") || metric.starts_with("replay_") ||
      metric.starts_with("policy_") || metric.starts_with("snapshot") || metric == "updates" ||
      metric == "chunks" || metric == "learner_epoch" || metric == "sequence_gaps" ||
      metric.starts_with("checkpoint") || metric == "failed_updates") {
    return "throughput and pacing";
  }
  return "other";
}

// The runs' evaluation videos, transcoded beside the page, as the page's videos section; counts
// them in `videos`.
std::string videos_section(const DashboardInput& input, const fs::path& page_dir,
                           std::size_t& videos) {
  std::ostringstream html;
  html << "<section id=\"videos\"><h2>Evaluation videos</h2>\n";
  for (const auto& group : input.runs) {
    for (const auto& run : group.runs) {
      const std::vector<fs::path> files = run_files(run / "videos", "", ".mp4");
      const std::string run_name = run.lexically_normal().filename().string();
      for (std::size_t i = 0; i < files.size() && i < kMaxVideosPerRun; ++i) {
        const fs::path target =
            page_dir / "media" / (run_name + "-" + files[i].stem().string() + ".webm");
        const auto video = browser_video(files[i], target);
        if (!video) continue;
        html << "<figure><video controls muted loop preload=\"metadata\" src=\"media/"
             << escape_html(video->filename().string()) << "\"></video><figcaption>"
             << escape_html(run_name + ": " + files[i].filename().string())
             << "</figcaption></figure>\n";
        ++videos;
      }
      if (files.size() > kMaxVideosPerRun) {
        html << "<p class=\"note\">" << files.size() - kMaxVideosPerRun << " more in "
             << escape_html((run / "videos").string()) << "</p>\n";
      }
    }
  }
  if (videos == 0) {
    html << "<p class=\"note\">no videos (evaluators record them with "
            "eval.video_episodes)</p>\n";
  }
  html << "</section>\n";

  return html.str();
}

namespace {

// The pieces of render_dashboard, one per part of the page.

// Every run of the page's groups; throws for an empty group or a folder that is no run.
std::vector<fs::path> run_dirs_of(const DashboardInput& input) {
  if (input.runs.empty()) throw std::invalid_argument("dashboard: name at least one run");
  std::vector<fs::path> all_runs;
  for (const auto& group : input.runs) {
    if (group.runs.empty()) throw std::invalid_argument("group '" + group.label + "' has no runs");
    for (const auto& run : group.runs) {
      if (!fs::exists(run / "metrics.jsonl") && !fs::is_directory(run / "eval") &&
          !fs::exists(run / "config.yaml")) {
        throw IoError(run.string() +
                      " has no metrics.jsonl, eval/ or config.yaml: is it a run directory (the "
                      "folder indrive launch or indrive-train-local --run-dir wrote)?");
      }
      all_runs.push_back(run);
    }
  }
  return all_runs;
}

// How the run stands, for the header: live, ended (as the caller or a one-run page's
// status.json says) or only when the page was written.
std::string state_html(const DashboardInput& input, const std::vector<fs::path>& all_runs) {
  const std::string now = local_time_now();
  std::string ended = input.ended;
  if (ended.empty() && input.live_refresh_s <= 0 && all_runs.size() == 1 &&
      fs::exists(all_runs[0] / "status.json")) {
    // A run that `indrive launch` ran to its end says so in its status file.
    try {
      const auto status = nlohmann::json::parse(read_text(all_runs[0] / "status.json"));
      if (status.value("state", "") == "ended") {
        ended = "ended " + status.value("written", std::string("?"));
      }
    } catch (const nlohmann::json::exception&) {
      // status_html names the broken file.
    }
  }
  std::ostringstream html;
  if (input.live_refresh_s > 0) {
    html << "<span class=\"live\">live</span>: written " << now << ", reloads every "
         << std::lround(input.live_refresh_s) << " s while the run goes on";
  } else if (!ended.empty()) {
    html << "<span class=\"ended\">" << escape_html(ended) << "</span>; page written " << now;
  } else {
    html << "written " << now;
  }
  return html.str();
}

std::string head_html(const DashboardInput& input, const std::string& title,
                      const std::vector<fs::path>& all_runs) {
  std::ostringstream html;
  html << "<!doctype html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">\n<title>indrive: "
       << escape_html(title) << "</title>\n";
  if (input.live_refresh_s > 0) {
    html << "<meta http-equiv=\"refresh\" content=\""
         << std::max(1, static_cast<int>(std::lround(input.live_refresh_s))) << "\">\n";
  }
  html << "<style>" << dashboard_style() << "</style>\n<script>" << chartjs_source()
       << "</script>\n";
  html << "</head><body>\n<header><h1>" << escape_html(title) << "</h1><div class=\"state\">"
       << state_html(input, all_runs);
  html << "</div><nav><a href=\"#curves\">curves</a><a href=\"#tables\">tables</a>"
          "<a href=\"#maps\">maps</a><a href=\"#videos\">videos</a><a href=\"#processes\">"
          "processes</a><a href=\"#config\">config</a></nav></header>\n<main>\n";
  return html.str();
}

// The charts' canvases, grouped; the page's script draws them from DATA.
std::string curves_section(const std::vector<Chart>& charts) {
  std::ostringstream html;
  html << "<section id=\"curves\"><h2>Curves</h2><div class=\"controls\">against "
       << "env steps; hover for values, drag across a chart to zoom, double-click to reset. "
       << "Smoothing <select id=\"smoothing\"><option value=\"0\">none</option>"
       << "<option value=\"0.6\">0.6</option><option value=\"0.9\">0.9</option>"
       << "<option value=\"0.97\">0.97</option></select> (series of 50 points or more)</div>\n";
  if (charts.empty()) html << "<p class=\"note\">no metrics yet</p>\n";
  std::string open_group;
  for (std::size_t c = 0; c < charts.size(); ++c) {
    if (charts[c].group != open_group) {
      if (!open_group.empty()) html << "</div>\n";
      open_group = charts[c].group;
      html << "<h3>" << escape_html(open_group) << "</h3><div class=\"grid\">\n";
    }
    html << "<div class=\"chart\"><canvas id=\"chart" << c << "\"></canvas></div>\n";
  }
  if (!open_group.empty()) html << "</div>\n";
  html << "</section>\n";
  return html.str();
}

// The report's tables over the runs' evaluations.
std::string tables_section(const DashboardInput& input, const std::vector<fs::path>& all_runs) {
  std::ostringstream html;
  html << "<section id=\"tables\"><h2>Tables</h2>\n";
  try {
    const Report report = aggregate(load_results(all_runs));
    const std::string route_set = route_set_of(all_runs);
    html << markdown_to_html(render_markdown(
        report, input.seen_town, input.heldout_town,
        route_set.empty() ? TownChoices{} : route_choices_of(report, route_set), route_set));
  } catch (const CsvError&) {  // load_results: no episode in any eval/*.csv yet
    html << "<p class=\"note\">no evaluation episodes yet (the runs' eval/*.csv)</p>\n";
  }
  html << "</section>\n";
  return html.str();
}

// Training episodes per route (train-episodes.csv), newest 5 of each route.
std::string training_section(const std::vector<fs::path>& all_runs) {
  constexpr int kLastEpisodes = 5;
  std::vector<RunTraining> trained;
  for (const fs::path& run : all_runs) {
    if (!fs::is_regular_file(run / "train-episodes.csv")) continue;
    try {
      trained.push_back(summarize_training(load_training_episodes(run), kLastEpisodes));
      trained.back().label = run.filename().string();
    } catch (const std::exception&) {  // no finished episode yet, or a file being written
    }
  }
  std::ostringstream html;
  html << "<section id=\"training\"><h2>Training per route</h2>\n";
  if (trained.empty()) {
    html << "<p class=\"note\">no finished training episodes yet (the runs' "
            "train-episodes.csv)</p>\n";
  } else {
    html << markdown_to_html(render_training(trained, kLastEpisodes));
  }
  html << "</section>\n";
  return html.str();
}

// Coverage and town maps from the runs' plots/, embedded; counts them into `pictures`.
std::string maps_section(const DashboardInput& input, std::size_t& pictures) {
  std::ostringstream html;
  html << "<section id=\"maps\"><h2>Coverage and town maps</h2>\n";
  for (const auto& group : input.runs) {
    for (const auto& run : group.runs) {
      std::vector<fs::path> pngs = run_files(run / "plots", "coverage_map", ".png");
      for (auto& town : run_files(run / "plots", "town", ".png")) pngs.push_back(std::move(town));
      for (const auto& png : pngs) {
        html << "<figure><img alt=\"" << escape_html(png.filename().string())
             << "\" src=\"data:image/png;base64," << base64(read_text(png)) << "\"><figcaption>"
             << escape_html(run.filename().string() + ": " + png.filename().string())
             << "</figcaption></figure>\n";
        ++pictures;
      }
    }
  }
  if (pictures == 0) {
    html << "<p class=\"note\">no coverage or town maps in the runs' plots/ (indrive plot RUN "
            "draws the coverage map)</p>\n";
  }
  html << "</section>\n";
  return html.str();
}

// The processes (status.json) and the resolved configs of the runs.
std::string processes_and_config_sections(const std::vector<fs::path>& all_runs) {
  std::ostringstream html;
  html << "<section id=\"processes\"><h2>Processes</h2>\n";
  bool any_status = false;
  for (const auto& run : all_runs) {
    if (!fs::exists(run / "status.json")) continue;
    any_status = true;
    html << "<h4>" << escape_html(run.string()) << "</h4>" << status_html(run / "status.json");
  }
  if (!any_status) {
    html << "<p class=\"note\">no status.json (written by indrive launch while it runs)</p>\n";
  }
  html << "</section>\n<section id=\"config\"><h2>Resolved config</h2>\n";
  for (const auto& run : all_runs) {
    if (!fs::exists(run / "config.yaml")) continue;
    html << "<details><summary>" << escape_html((run / "config.yaml").string()) << "</summary><pre>"
         << escape_html(read_text(run / "config.yaml")) << "</pre></details>\n";
  }
  html << "</section>\n";
  return html.str();
}

}  // namespace

std::string render_dashboard(const DashboardInput& input, const fs::path& page_dir,
                             DashboardStats* stats, DashboardCache* cache) {
  const std::vector<fs::path> all_runs = run_dirs_of(input);
  std::string title = input.title;
  if (title.empty()) {
    for (const auto& group : input.runs) title += (title.empty() ? "" : ", ") + group.label;
  }
  const std::vector<Chart> charts = build_charts(input.runs, cache);
  std::size_t points = 0;
  const std::string data = charts_json(charts, &points);
  std::size_t videos = 0, pictures = 0;
  const std::string videos_html = videos_section(input, page_dir, videos);

  std::ostringstream html;
  html << head_html(input, title, all_runs);
  // Videos first where they are the point of the page (the main job's learned policy).
  if (input.videos_first) html << videos_html;
  html << curves_section(charts) << tables_section(input, all_runs) << training_section(all_runs)
       << maps_section(input, pictures);
  if (!input.videos_first) html << videos_html;
  html << processes_and_config_sections(all_runs);
  html << "</main>\n<script>const DATA = {\"x_key\":\"env_steps\"," << data.substr(1) << ";\n"
       << dashboard_script() << "</script>\n</body></html>\n";
  if (stats != nullptr) {
    stats->charts = charts.size();
    stats->points = points;
    stats->videos = videos;
    stats->pictures = pictures;
  }
  return html.str();
}

DashboardStats write_dashboard(const DashboardInput& input, const fs::path& page,
                               DashboardCache* cache) {
  const auto start = std::chrono::steady_clock::now();
  DashboardStats stats;
  const fs::path dir = page.has_parent_path() ? page.parent_path() : fs::path(".");
  fs::create_directories(dir);
  const std::string html = render_dashboard(input, dir, &stats, cache);
  atomic_write(page, html);
  stats.page = page;
  stats.bytes = html.size();
  stats.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return stats;
}

}  // namespace indrive::deploy
