#include "indrive/deploy/plot.h"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <limits>
#include <map>
#include <memory>
#include <mutex>
#include <nlohmann/json.hpp>
#include <opencv2/imgproc.hpp>
#include <sstream>
#include <stdexcept>

#include "indrive/basics/run_dir.h"
#include "indrive/envserver/coverage.h"
#include "indrive/envserver/town.h"

namespace indrive::deploy {

MetricsFollower::MetricsFollower(std::filesystem::path metrics_jsonl, std::string x_key)
    : path_(std::move(metrics_jsonl)), x_key_(std::move(x_key)) {}

void MetricsFollower::add_line(const std::string& line, bool last_of_file) {
  ++line_number_;
  if (line.empty()) return;
  nlohmann::json record;
  try {
    record = nlohmann::json::parse(line);
  } catch (const nlohmann::json::exception&) {
    // The last line of a crashed run may be cut short; anything else is corrupt.
    if (last_of_file) return;
    throw IoError(path_.string() + ":" + std::to_string(line_number_) + ": not JSON");
  }
  const auto x_value = record.find(x_key_);
  if (x_value == record.end() || !x_value->is_number()) return;
  const double x = x_value->get<double>();
  for (const auto& [key, value] : record.items()) {
    if (key == x_key_ || key == "time" || !value.is_number()) continue;
    auto& column = columns_[key];
    column.first.push_back(x);
    column.second.push_back(value.get<double>());
  }
}

const MetricColumns& MetricsFollower::update(bool final) {
  std::error_code error;
  const std::uintmax_t size = std::filesystem::file_size(path_, error);
  if (error) return columns_;  // not written yet
  if (size < offset_) {        // replaced by a shorter file: start again
    offset_ = 0;
    line_number_ = 0;
    columns_.clear();
  }
  if (size == offset_) return columns_;
  std::ifstream in(path_, std::ios::binary);
  if (!in) throw IoError("cannot open " + path_.string());
  in.seekg(static_cast<std::streamoff>(offset_));
  std::string text(size - offset_, '\0');
  in.read(text.data(), static_cast<std::streamsize>(text.size()));
  text.resize(static_cast<std::size_t>(in.gcount()));
  std::size_t begin = 0;
  for (std::size_t end; (end = text.find('\n', begin)) != std::string::npos; begin = end + 1) {
    // A complete line; a cut one is only forgiven at the very end of the file.
    add_line(text.substr(begin, end - begin), /*last_of_file=*/final && end + 1 == text.size());
  }
  if (final && begin < text.size()) {
    add_line(text.substr(begin), /*last_of_file=*/true);
    begin = text.size();
  }
  offset_ += begin;
  return columns_;
}

MetricColumns read_metric_columns(const std::filesystem::path& metrics_jsonl,
                                  const std::string& x_key) {
  if (!std::filesystem::exists(metrics_jsonl))
    throw IoError("cannot open " + metrics_jsonl.string());
  MetricsFollower follower(metrics_jsonl, x_key);
  follower.update(/*final=*/true);
  MetricColumns columns = follower.columns();
  return columns;
}

std::vector<std::filesystem::path> plot_metrics(const std::filesystem::path& metrics_jsonl,
                                                const std::filesystem::path& out_dir,
                                                const std::string& x_key) {
  MetricColumns columns = read_metric_columns(metrics_jsonl, x_key);
  std::filesystem::create_directories(out_dir);
  std::vector<std::filesystem::path> written;
  for (auto& [key, xy] : columns) {
    LinePlot plot(key, x_key, key);
    plot.set_smoothing(0.9);
    plot.add_series(key, std::move(xy.first), std::move(xy.second));
    std::string file = key;
    std::replace_if(
        file.begin(), file.end(), [](char c) { return !std::isalnum(c) && c != '_'; }, '_');
    const auto path = out_dir / (file + ".png");
    plot.save(path);
    written.push_back(path);
  }
  return written;
}

MeanBand mean_band(const std::vector<std::pair<std::vector<double>, std::vector<double>>>& runs,
                   int points) {
  if (runs.empty() || points < 2) {
    throw std::invalid_argument("mean_band needs at least one run and two points");
  }
  // Each run's finite points, sorted by x (a resumed run may log an x again: the later wins).
  std::vector<std::vector<std::pair<double, double>>> sorted;
  double from = -std::numeric_limits<double>::infinity();
  double to = std::numeric_limits<double>::infinity();
  for (std::size_t r = 0; r < runs.size(); ++r) {
    const auto& [xs, ys] = runs[r];
    std::vector<std::pair<double, double>> run;
    for (std::size_t i = 0; i < std::min(xs.size(), ys.size()); ++i) {
      if (std::isfinite(xs[i]) && std::isfinite(ys[i])) run.emplace_back(xs[i], ys[i]);
    }
    if (run.empty()) {
      throw std::invalid_argument("run " + std::to_string(r + 1) + " has no finite points");
    }
    std::stable_sort(run.begin(), run.end(),
                     [](const auto& a, const auto& b) { return a.first < b.first; });
    from = std::max(from, run.front().first);
    to = std::min(to, run.back().first);
    sorted.push_back(std::move(run));
  }
  if (from > to) {
    throw std::invalid_argument("the runs cover no common x range (one ends at " +
                                std::to_string(to) + ", another starts at " + std::to_string(from) +
                                ")");
  }
  const auto at = [](const std::vector<std::pair<double, double>>& run, double x) {
    // The last point at or before x and the first after it.
    const auto after = std::upper_bound(run.begin(), run.end(), x,
                                        [](double v, const auto& p) { return v < p.first; });
    if (after == run.begin()) return run.front().second;
    const auto& a = *(after - 1);
    if (after == run.end() || a.first == x) return a.second;
    return a.second + (after->second - a.second) * (x - a.first) / (after->first - a.first);
  };
  MeanBand band;
  const int n = from == to ? 1 : points;
  for (int i = 0; i < n; ++i) {
    const double x = n == 1 ? from : from + (to - from) * i / (n - 1);
    double sum = 0.0, low = std::numeric_limits<double>::infinity(), high = -low;
    for (const auto& run : sorted) {
      const double y = at(run, x);
      sum += y;
      low = std::min(low, y);
      high = std::max(high, y);
    }
    band.x.push_back(x);
    band.mean.push_back(sum / static_cast<double>(sorted.size()));
    band.low.push_back(low);
    band.high.push_back(high);
  }
  return band;
}

CompareGroup single_run_group(const std::filesystem::path& run) {
  // A trailing slash would leave the folder name empty.
  const auto normal = run.lexically_normal();
  return {normal.filename().empty() ? normal.parent_path().filename().string()
                                    : normal.filename().string(),
          {run}};
}

CompareGroup parse_compare_group(const std::string& spec) {
  const auto equals = spec.find('=');
  const char* form = "': write LABEL=RUN[,RUN...], e.g. disag=runs/s0/disag,runs/s1/disag";
  if (equals == std::string::npos || equals == 0 || equals + 1 == spec.size()) {
    throw std::invalid_argument("group '" + spec + form);
  }
  CompareGroup group{spec.substr(0, equals), {}};
  std::istringstream runs(spec.substr(equals + 1));
  for (std::string run; std::getline(runs, run, ',');) {
    if (run.empty()) throw std::invalid_argument("group '" + spec + "' names an empty run" + form);
    group.runs.emplace_back(run);
  }
  return group;
}

std::vector<CompareEnd> plot_compare(const std::vector<CompareGroup>& groups,
                                     const std::string& metric,
                                     const std::filesystem::path& png_path,
                                     const std::string& x_key, double smoothing) {
  if (groups.empty()) throw std::invalid_argument("plot_compare needs at least one run");
  LinePlot plot(metric, x_key, metric);
  std::vector<CompareEnd> ends;
  for (const auto& group : groups) {
    if (group.runs.empty()) {
      throw std::invalid_argument("group '" + group.label + "' has no runs");
    }
    std::vector<std::pair<std::vector<double>, std::vector<double>>> series;
    for (const auto& run : group.runs) {
      const auto metrics = run / "metrics.jsonl";
      MetricColumns columns = read_metric_columns(metrics, x_key);
      auto found = columns.find(metric);
      if (found == columns.end()) {
        throw IoError(metrics.string() + " has no numeric '" + metric + "' against '" + x_key +
                      "': see indrive plot " + run.string() + " for the metrics it has");
      }
      series.push_back(std::move(found->second));
    }
    if (series.size() == 1) {
      auto& [xs, ys] = series[0];
      for (std::size_t i = xs.size(); i-- > 0;) {
        if (std::isfinite(xs[i]) && std::isfinite(ys[i])) {
          ends.push_back({group.label, xs[i], ys[i], ys[i], ys[i]});
          break;
        }
      }
      plot.add_series(group.label, std::move(xs), std::move(ys));
      continue;
    }
    MeanBand band;
    try {
      band = mean_band(series);
    } catch (const std::invalid_argument& error) {
      throw std::invalid_argument("group '" + group.label + "': " + error.what());
    }
    const std::string label =
        group.label + " (mean of " + std::to_string(series.size()) + ", band min-max)";
    ends.push_back({label, band.x.back(), band.mean.back(), band.low.back(), band.high.back()});
    plot.add_series(label, std::move(band.x), std::move(band.mean), std::move(band.low),
                    std::move(band.high));
  }
  plot.set_smoothing(smoothing);
  if (png_path.has_parent_path()) std::filesystem::create_directories(png_path.parent_path());
  plot.save(png_path);
  return ends;
}

EvalCurves read_eval_curves(const std::vector<std::filesystem::path>& files) {
  struct Sum {
    int episodes = 0;
    int successes = 0;
    double completion = 0.0;
  };
  std::map<std::string, std::map<double, Sum>> sums;
  for (const auto& path : files) {
    std::ifstream in(path);
    if (!in) throw IoError("cannot open " + path.string());
    std::string header;
    std::getline(in, header);
    std::map<std::string, std::size_t> column;
    {
      std::istringstream fields(header);
      std::size_t index = 0;
      for (std::string name; std::getline(fields, name, ',');) column[name] = index++;
    }
    for (const char* name : {"env_steps", "town", "success", "route_completion"}) {
      if (!column.contains(name)) {
        throw IoError(path.string() + " has no '" + name +
                      "' column: is it a learning curve written by indrive-actor --continuous?");
      }
    }
    const std::size_t width = column.size();
    int number = 1;
    for (std::string line; std::getline(in, line);) {
      ++number;
      if (line.empty()) continue;
      std::vector<std::string> fields;
      std::istringstream split(line);
      for (std::string field; std::getline(split, field, ',');) fields.push_back(field);
      if (!line.empty() && line.back() == ',') fields.emplace_back();
      const auto bad = [&](const std::string& what) {
        return IoError(path.string() + ":" + std::to_string(number) + ": " + what);
      };
      try {
        if (fields.size() != width) throw bad("expected " + std::to_string(width) + " fields");
        const double steps = std::stod(fields[column["env_steps"]]);
        const int success = std::stoi(fields[column["success"]]);
        const double completion = std::stod(fields[column["route_completion"]]);
        if (success != 0 && success != 1) throw bad("success must be 0 or 1");
        const auto reason = column.find("failure_reason");
        if (reason != column.end() && fields[reason->second] == "env_fault") continue;
        Sum& sum = sums[fields[column["town"]]][steps];
        ++sum.episodes;
        sum.successes += success;
        sum.completion += completion;
      } catch (const std::logic_error&) {  // std::stod / std::stoi on a non-number
        if (in.peek() == EOF) break;       // the cut last line of a crashed evaluator
        throw bad("not a number where one is expected");
      } catch (const IoError&) {
        if (in.peek() == EOF) break;
        throw;
      }
    }
  }
  EvalCurves curves;
  for (const auto& [town, by_steps] : sums) {
    for (const auto& [steps, sum] : by_steps) {
      curves[town].push_back({.env_steps = steps,
                              .episodes = sum.episodes,
                              .success_rate = double(sum.successes) / sum.episodes,
                              .route_completion = sum.completion / sum.episodes});
    }
  }
  return curves;
}

std::vector<std::filesystem::path> run_files(const std::filesystem::path& folder,
                                             const std::string& prefix, const std::string& suffix) {
  std::vector<std::filesystem::path> files;
  if (!std::filesystem::is_directory(folder)) return files;
  for (const auto& entry : std::filesystem::directory_iterator(folder)) {
    const std::string name = entry.path().filename().string();
    if (entry.is_regular_file() && name.starts_with(prefix) && name.ends_with(suffix) &&
        name.size() >= prefix.size() + suffix.size()) {
      files.push_back(entry.path());
    }
  }
  std::sort(files.begin(), files.end());
  return files;
}

std::vector<std::filesystem::path> plot_eval_curves(const std::filesystem::path& run_dir,
                                                    const std::filesystem::path& out_dir) {
  namespace fs = std::filesystem;
  const EvalCurves curves = read_eval_curves(run_files(run_dir / "eval", "curve-", ".csv"));
  if (curves.empty()) return {};
  LinePlot success("evaluation success rate (continuous evaluator)", "env steps", "SR %");
  LinePlot completion("evaluation route completion (continuous evaluator)", "env steps",
                      "mean route completion %");
  for (const auto& [town, points] : curves) {
    std::vector<double> x, sr, rc;
    for (const auto& point : points) {
      x.push_back(point.env_steps);
      sr.push_back(100.0 * point.success_rate);
      rc.push_back(100.0 * point.route_completion);
    }
    success.add_series(town, x, std::move(sr));
    completion.add_series(town, std::move(x), std::move(rc));
  }
  fs::create_directories(out_dir);
  const std::vector<fs::path> written = {out_dir / "eval_success_rate.png",
                                         out_dir / "eval_route_completion.png"};
  success.save(written[0]);
  completion.save(written[1]);
  return written;
}

namespace {

// A town and its lane segments, loaded once per process: the launcher and `indrive dashboard
// --watch` redraw a run's coverage map every refresh, and loading the town is most of a redraw.
struct SegmentedTown {
  env::Town town;
  std::unique_ptr<env::LaneSegments> segments;  // points into town.net: both live here
};

const SegmentedTown& segmented_town(const std::string& spec, double segment_m) {
  static std::mutex mutex;
  static std::map<std::pair<std::string, double>, std::unique_ptr<SegmentedTown>> towns;
  std::lock_guard<std::mutex> lock(mutex);
  auto& entry = towns[{spec, segment_m}];
  if (!entry) {
    auto loaded = std::make_unique<SegmentedTown>(SegmentedTown{env::load_town(spec), nullptr});
    loaded->segments = std::make_unique<env::LaneSegments>(loaded->town.net, segment_m);
    entry = std::move(loaded);
  }
  return *entry;
}

}  // namespace

std::optional<std::filesystem::path> plot_coverage(const std::filesystem::path& run_dir,
                                                   const std::filesystem::path& png_path) {
  namespace fs = std::filesystem;
  std::vector<fs::path> files;
  if (fs::exists(run_dir / "coverage.csv")) files.push_back(run_dir / "coverage.csv");
  if (fs::is_directory(run_dir / "coverage")) {
    std::vector<fs::path> actors;
    for (const auto& entry : fs::directory_iterator(run_dir / "coverage")) {
      if (entry.path().extension() == ".csv") actors.push_back(entry.path());
    }
    std::sort(actors.begin(), actors.end());
    files.insert(files.end(), actors.begin(), actors.end());
  }
  if (files.empty()) return std::nullopt;

  // The training town of the run, as its resolved config names it.
  std::string town_spec = "town01";
  const fs::path config_path = run_dir / "config.yaml";
  if (fs::exists(config_path)) {
    try {
      const YAML::Node config = YAML::LoadFile(config_path.string());
      if (config["env"] && config["env"]["town"])
        town_spec = config["env"]["town"].as<std::string>();
    } catch (const YAML::Exception& error) {
      throw IoError(config_path.string() + " is not readable YAML: " + error.what());
    }
  }
  const env::CoverageCounts counts = env::read_coverage_csv(files);
  const SegmentedTown& loaded = segmented_town(town_spec, counts.segment_m);
  const env::Town& town = loaded.town;
  const env::LaneSegments& segments = *loaded.segments;
  int visited = 0;
  for (std::size_t i = 0; i < counts.pieces.size(); ++i) {
    if (counts.visits[i] > 0 &&
        segments.find(counts.pieces[i].first, counts.pieces[i].second) >= 0) {
      ++visited;
    }
  }
  std::ostringstream title;
  title << std::fixed << std::setprecision(1) << "coverage " << town.name << ": " << counts.steps
        << " env steps, " << counts.distinct_per_1k << " distinct segments / 1k steps, "
        << 100.0 * visited / std::max(1, segments.count()) << "% of " << segments.count()
        << " segments (" << counts.segment_m << " m) visited";
  env::draw_coverage(town.net, counts, png_path, title.str());
  return png_path;
}

}  // namespace indrive::deploy
