#include "indrive/envserver/coverage.h"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <map>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <sstream>
#include <stdexcept>

#include "indrive/basics/check.h"
#include "indrive/basics/run_dir.h"

namespace indrive::env {

LaneSegments::LaneSegments(const RoadNetwork& net, double segment_m)
    : net_(&net), segment_m_(segment_m) {
  if (!(segment_m > 0.0)) {
    throw std::invalid_argument("coverage segment length must be positive, got " +
                                std::to_string(segment_m));
  }
  first_.reserve(net.lanes().size());
  for (std::size_t lane = 0; lane < net.lanes().size(); ++lane) {
    first_.push_back(static_cast<int>(lane_of_.size()));
    // A lane of length L has ceil(L / segment_m) pieces, at least one (short internal lanes).
    const int pieces =
        std::max(1, static_cast<int>(std::ceil(net.lanes()[lane].length_m / segment_m - 1e-9)));
    lane_of_.insert(lane_of_.end(), pieces, static_cast<int>(lane));
  }
}

int LaneSegments::segment(int lane, double s_m) const {
  INDRIVE_CHECK(lane >= 0 && lane < static_cast<int>(first_.size())) << "lane " << lane;
  const int next = lane + 1 < static_cast<int>(first_.size()) ? first_[lane + 1] : count();
  const int pieces = next - first_[lane];
  const int piece = std::clamp(static_cast<int>(std::floor(s_m / segment_m_)), 0, pieces - 1);
  return first_[lane] + piece;
}

std::optional<int> LaneSegments::locate(const Pose2& pose) const {
  const auto at = net_->locate({pose.x_m, pose.y_m}, pose.yaw_rad);
  if (!at) return std::nullopt;
  return segment(at->lane, at->s_m);
}

int LaneSegments::find(const std::string& lane_id, int piece) const {
  const int lane = net_->find_lane(lane_id);
  if (lane < 0 || piece < 0) return -1;
  const int next = lane + 1 < static_cast<int>(first_.size()) ? first_[lane + 1] : count();
  return first_[lane] + piece < next ? first_[lane] + piece : -1;
}

std::pair<double, double> LaneSegments::range_m(int segment) const {
  const double length = net_->lane(lane_of(segment)).length_m;
  const double start = piece_of(segment) * segment_m_;
  return {std::min(start, length), std::min(start + segment_m_, length)};
}

CoverageTracker::CoverageTracker(const RoadNetwork& net, CoverageOptions options)
    : segments_(net, options.segment_m),
      options_(options),
      visits_(segments_.count(), 0),
      last_window_(segments_.count(), -1),
      last_episode_(segments_.count(), -1) {
  if (options.window_steps < 1) {
    throw std::invalid_argument("coverage window must hold at least one step");
  }
}

void CoverageTracker::observe(const Pose2& pose) {
  const std::int64_t window = session_steps_ / options_.window_steps;
  if (const auto piece = segments_.locate(pose)) {
    ++visits_[*piece];
    if (last_window_[*piece] != window) {
      last_window_[*piece] = window;
      ++current_distinct_;
    }
    if (last_episode_[*piece] != episode_) {
      last_episode_[*piece] = episode_;
      ++episode_distinct_;
    }
  }
  ++episode_step_count_;
  ++steps_;
  ++session_steps_;
  if (session_steps_ % options_.window_steps == 0) {
    window_scores_.push_back(current_distinct_);
    current_distinct_ = 0;
  }
}

void CoverageTracker::end_episode() {
  if (episode_step_count_ == 0) return;
  episode_reach_.push_back(episode_distinct_);
  episode_steps_.push_back(episode_step_count_);
  episode_distinct_ = 0;
  episode_step_count_ = 0;
  ++episode_;
}

double CoverageTracker::distinct_per_window() const {
  if (!window_scores_.empty() || restored_windows_ > 0) {
    double sum = restored_window_sum_;
    for (const int score : window_scores_) sum += score;
    return sum / static_cast<double>(window_scores_.size() + restored_windows_);
  }
  if (session_steps_ == 0) return restored_partial_;
  return current_distinct_ * static_cast<double>(options_.window_steps) / session_steps_;
}

void CoverageTracker::restore(const CoverageCounts& counts) {
  for (std::size_t i = 0; i < counts.pieces.size(); ++i) {
    const int piece = segments_.find(counts.pieces[i].first, counts.pieces[i].second);
    if (piece >= 0) visits_[piece] += counts.visits[i];
  }
  steps_ += counts.steps;
  restored_windows_ += counts.windows;
  restored_window_sum_ += counts.distinct_per_1k * static_cast<double>(counts.windows);
  if (counts.windows == 0) restored_partial_ = counts.distinct_per_1k;
}

int CoverageTracker::segments_visited() const {
  return static_cast<int>(
      std::count_if(visits_.begin(), visits_.end(), [](std::int64_t v) { return v > 0; }));
}

double CoverageTracker::fraction_visited() const {
  return segments_.count() == 0 ? 0.0 : static_cast<double>(segments_visited()) / segments_.count();
}

void CoverageTracker::write_csv(const std::filesystem::path& path) const {
  std::ostringstream out;
  out << "# steps=" << steps_ << " windows=" << window_scores_.size() + restored_windows_
      << " distinct_per_1k=" << distinct_per_window() << " fraction_visited=" << fraction_visited()
      << " segments=" << segments_.count() << " segment_m=" << segments_.segment_m() << "\n";
  out << "lane,piece,visits\n";
  for (int piece = 0; piece < segments_.count(); ++piece) {
    if (visits_[piece] == 0) continue;
    out << segments_.net().lane(segments_.lane_of(piece)).id << ',' << segments_.piece_of(piece)
        << ',' << visits_[piece] << '\n';
  }
  if (!path.parent_path().empty()) std::filesystem::create_directories(path.parent_path());
  atomic_write(path, out.str());
}

namespace {

// Reads `key=value` pairs of a summary line ("# a=1 b=2").
std::map<std::string, double> parse_summary(const std::string& line) {
  std::map<std::string, double> values;
  std::istringstream in(line.substr(1));
  for (std::string item; in >> item;) {
    const auto eq = item.find('=');
    if (eq == std::string::npos) continue;
    try {
      values[item.substr(0, eq)] = std::stod(item.substr(eq + 1));
    } catch (const std::exception&) {
      // An unreadable summary value is left out; the rows carry the data.
    }
  }
  return values;
}

}  // namespace

CoverageCounts read_coverage_csv(const std::vector<std::filesystem::path>& files) {
  CoverageCounts counts;
  std::map<std::pair<std::string, int>, std::size_t> index;
  double weighted_windows = 0.0, weighted_steps = 0.0, steps_only = 0.0;
  bool first_file = true;
  for (const auto& file : files) {
    std::ifstream in(file);
    if (!in) throw IoError("cannot open coverage file " + file.string());
    int number = 0;
    bool header = false;
    for (std::string line; std::getline(in, line);) {
      ++number;
      if (line.empty()) continue;
      if (line[0] == '#') {
        const auto summary = parse_summary(line);
        const auto get = [&](const char* key) {
          const auto it = summary.find(key);
          return it == summary.end() ? 0.0 : it->second;
        };
        const double steps = get("steps"), windows = get("windows"),
                     per_1k = get("distinct_per_1k");
        counts.steps += static_cast<std::int64_t>(steps);
        counts.windows += static_cast<std::int64_t>(windows);
        weighted_windows += windows * per_1k;
        weighted_steps += steps * per_1k;
        steps_only += steps;
        if (first_file && summary.contains("segment_m")) counts.segment_m = get("segment_m");
        continue;
      }
      if (!header) {
        if (line != "lane,piece,visits") {
          throw IoError(file.string() + ":" + std::to_string(number) +
                        ": expected the header 'lane,piece,visits'; is this a coverage file?");
        }
        header = true;
        continue;
      }
      const auto c1 = line.rfind(',');
      const auto c0 =
          c1 == std::string::npos || c1 == 0 ? std::string::npos : line.rfind(',', c1 - 1);
      try {
        if (c0 == std::string::npos) throw std::invalid_argument("fields");
        std::size_t used = 0;
        const int piece = std::stoi(line.substr(c0 + 1, c1 - c0 - 1), &used);
        const long long visits = std::stoll(line.substr(c1 + 1));
        if (piece < 0 || visits < 0) throw std::invalid_argument("negative");
        const auto key = std::make_pair(line.substr(0, c0), piece);
        auto [it, inserted] = index.emplace(key, counts.pieces.size());
        if (inserted) {
          counts.pieces.push_back(key);
          counts.visits.push_back(0);
        }
        counts.visits[it->second] += visits;
      } catch (const std::exception&) {
        throw IoError(file.string() + ":" + std::to_string(number) +
                      ": expected 'lane,piece,visits' with a piece index and a visit count, got '" +
                      line + "'");
      }
    }
    first_file = false;
  }
  if (counts.windows > 0) {
    counts.distinct_per_1k = weighted_windows / static_cast<double>(counts.windows);
  } else if (steps_only > 0) {
    counts.distinct_per_1k = weighted_steps / steps_only;
  }
  return counts;
}

void draw_coverage(const RoadNetwork& net, const CoverageCounts& counts,
                   const std::filesystem::path& png_path, const std::string& title,
                   double pixels_per_m) {
  const LaneSegments segments(net, counts.segment_m);
  std::vector<std::int64_t> visits(segments.count(), 0);
  std::int64_t most = 0;
  for (std::size_t i = 0; i < counts.pieces.size(); ++i) {
    const int piece = segments.find(counts.pieces[i].first, counts.pieces[i].second);
    if (piece < 0) continue;
    visits[piece] += counts.visits[i];
    most = std::max(most, visits[piece]);
  }

  // Layout: title band on top, the map, a colour bar on the right.
  const int title_px = 40, bar_px = 110, margin_px = 15;
  const Eigen::Vector2d lo = net.min_corner(), hi = net.max_corner();
  const int map_w = static_cast<int>(std::ceil((hi.x() - lo.x()) * pixels_per_m)) + 2 * margin_px;
  const int map_h = static_cast<int>(std::ceil((hi.y() - lo.y()) * pixels_per_m)) + 2 * margin_px;
  const int width = std::max(map_w + bar_px, 480);
  const int height = std::max(map_h + title_px, 260);
  cv::Mat image(height, width, CV_8UC3, cv::Scalar(255, 255, 255));
  const auto px = [&](const Eigen::Vector2d& p) {
    // North up, fixed point with 3 fractional bits for smooth lines.
    return cv::Point(
        static_cast<int>(std::lround((margin_px + (p.x() - lo.x()) * pixels_per_m) * 8)),
        static_cast<int>(
            std::lround((title_px + margin_px + (hi.y() - p.y()) * pixels_per_m) * 8)));
  };

  // Colours from a 256-entry map: index 0 = 1 visit, 255 = the most visits, on log(1 + v).
  cv::Mat ramp(1, 256, CV_8UC1);
  for (int i = 0; i < 256; ++i) ramp.at<std::uint8_t>(0, i) = static_cast<std::uint8_t>(i);
  cv::Mat lut;
  cv::applyColorMap(ramp, lut, cv::COLORMAP_VIRIDIS);
  const double log_most = std::log1p(static_cast<double>(std::max<std::int64_t>(most, 1)));
  const auto colour_of = [&](std::int64_t v) {
    const double t = most <= 1 ? 1.0
                               : (std::log1p(static_cast<double>(v)) - std::log1p(1.0)) /
                                     (log_most - std::log1p(1.0));
    const cv::Vec3b c = lut.at<cv::Vec3b>(0, std::clamp(static_cast<int>(t * 255.0), 0, 255));
    return cv::Scalar(c[0], c[1], c[2]);
  };

  // Unvisited pieces first (grey), visited ones over them, least visited first.
  const int thickness = std::max(2, static_cast<int>(std::lround(1.6 * pixels_per_m)));
  std::vector<int> order(segments.count());
  for (int i = 0; i < segments.count(); ++i) order[i] = i;
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) { return visits[a] < visits[b]; });
  for (const int piece : order) {
    const auto [s0, s1] = segments.range_m(piece);
    const int lane = segments.lane_of(piece);
    std::vector<cv::Point> line;
    const int steps = std::max(1, static_cast<int>(std::ceil((s1 - s0) / 1.0)));
    for (int k = 0; k <= steps; ++k) {
      const Pose2 p = net.lane_pose(lane, s0 + (s1 - s0) * k / steps);
      line.push_back(px({p.x_m, p.y_m}));
    }
    const cv::Scalar colour =
        visits[piece] > 0 ? colour_of(visits[piece]) : cv::Scalar(205, 205, 205);
    cv::polylines(image, line, false, colour, thickness, cv::LINE_AA, 3);
  }

  // Title.
  const int font = cv::FONT_HERSHEY_SIMPLEX;
  cv::putText(image, title, {10, 26}, font, 0.5, {0, 0, 0}, 1, cv::LINE_AA);

  // Colour bar with ticks at powers of ten (log scale), labelled in visits.
  const int bar_x = width - bar_px + 20, bar_top = title_px + 20;
  const int bar_h = std::max(100, height - title_px - 60);
  for (int y = 0; y < bar_h; ++y) {
    const int i = 255 - y * 255 / std::max(1, bar_h - 1);
    const cv::Vec3b c = lut.at<cv::Vec3b>(0, i);
    cv::line(image, {bar_x, bar_top + y}, {bar_x + 18, bar_top + y}, cv::Scalar(c[0], c[1], c[2]));
  }
  cv::rectangle(image, {bar_x, bar_top}, {bar_x + 18, bar_top + bar_h}, {0, 0, 0});
  cv::putText(image, "visits", {bar_x - 6, bar_top - 6}, font, 0.4, {0, 0, 0}, 1, cv::LINE_AA);
  if (most > 1) {
    for (double tick = 1.0; tick <= static_cast<double>(most) * 1.0001; tick *= 10.0) {
      const double t = (std::log1p(tick) - std::log1p(1.0)) / (log_most - std::log1p(1.0));
      const int y = bar_top + bar_h - 1 - static_cast<int>(t * (bar_h - 1));
      cv::line(image, {bar_x + 18, y}, {bar_x + 23, y}, {0, 0, 0});
      std::ostringstream label;
      label << static_cast<long long>(tick);
      cv::putText(image, label.str(), {bar_x + 26, y + 4}, font, 0.35, {0, 0, 0}, 1, cv::LINE_AA);
    }
  }
  std::ostringstream top;
  top << most;
  cv::putText(image, top.str(), {bar_x + 26, bar_top + 4}, font, 0.35, {0, 0, 0}, 1, cv::LINE_AA);
  cv::line(image, {bar_x, bar_top + bar_h + 14}, {bar_x + 18, bar_top + bar_h + 14},
           cv::Scalar(205, 205, 205), 6);
  cv::putText(image, "0", {bar_x + 26, bar_top + bar_h + 18}, font, 0.35, {0, 0, 0}, 1,
              cv::LINE_AA);

  std::vector<std::uint8_t> png;
  if (!cv::imencode(".png", image, png)) throw IoError("cannot encode " + png_path.string());
  if (!png_path.parent_path().empty()) std::filesystem::create_directories(png_path.parent_path());
  atomic_write(png_path, png);
}

}  // namespace indrive::env
