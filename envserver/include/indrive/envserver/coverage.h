// Exploration coverage: how much of a town's road network an agent drives over.
//
// The town's lanes (normal and junction-internal) are cut into fixed-length pieces along their
// centre lines, `segment_m` long (10 m by default; a lane's last piece may be shorter). Every
// env step maps the ego's pose to the piece it stands on (the lane of RoadNetwork::locate with
// the ego's heading, then floor(s / segment_m)) and counts a visit there. A step off every lane
// counts toward the step windows but visits no piece.
//
// Two measures come out of it:
//   - distinct lane segments per 1,000 env steps: the env steps are cut into consecutive
//     windows of 1,000 (window_steps) steps in the order they were taken, across episode
//     boundaries; each window scores the number of distinct pieces visited within it; the
//     measure is the mean score over the completed windows. Until the first window completes it
//     is the partial window's score scaled to 1,000 steps. A policy that parks scores about 1, a
//     policy that drives the same loop over and over scores the loop's pieces, one that keeps
//     reaching new streets scores the most.
//   - fraction visited: pieces visited at least once over all steps / all pieces of the town.
// Both count pieces reached by driving and pieces reached by being spawned there alike. A
// third measure tells them apart:
//   - reach per episode: the distinct pieces one episode visits, from its spawn piece to where
//     it ends. A policy that ends its episodes within metres (off the road, into a car) reaches
//     a handful; one that keeps driving into streets it has not seen reaches many. Episodes are
//     delimited by end_episode(); this session's episodes only (not restored).
//
//   CoverageTracker coverage(town.net);
//   for each env step: coverage.observe(result.ego.pose);
//   double per_1k = coverage.distinct_per_window();
//   coverage.write_csv(run_dir / "coverage.csv");       // lane,piece,visits (+ a summary line)
//   draw_coverage(town.net, read_coverage_csv(files), 10.0, "coverage.png", "title");
#pragma once

#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "indrive/envserver/net.h"
#include "indrive/envserver/scene.h"

namespace indrive::env {

// Settings of the coverage measure.
struct CoverageOptions {
  double segment_m = 10.0;           // length of a lane piece
  std::int64_t window_steps = 1000;  // env steps per window of the distinct-segments measure
};

// The town's lane pieces, numbered lane by lane in RoadNetwork::lanes() order.
class LaneSegments {
 public:
  // Cuts every lane of `net` into pieces of `segment_m` metres; throws std::invalid_argument
  // when segment_m is not positive. The network must outlive this object.
  LaneSegments(const RoadNetwork& net, double segment_m);

  // Number of pieces in the town.
  int count() const { return static_cast<int>(lane_of_.size()); }
  // Returns the piece of lane `lane` at arc length `s_m` (clamped to the lane).
  int segment(int lane, double s_m) const;
  // Returns the piece under a pose (the lane whose direction fits the heading best), or
  // nullopt when the pose is off every lane.
  std::optional<int> locate(const Pose2& pose) const;
  // Returns the piece with this lane id and piece index, or -1 when there is none.
  int find(const std::string& lane_id, int piece) const;
  // The lane index (into RoadNetwork::lanes()) of a piece.
  int lane_of(int segment) const { return lane_of_.at(segment); }
  // The index of a piece along its lane (0 at the lane's start).
  int piece_of(int segment) const { return segment - first_.at(lane_of_.at(segment)); }
  // Arc-length range [start, end] of a piece on its lane, in metres.
  std::pair<double, double> range_m(int segment) const;
  double segment_m() const { return segment_m_; }
  const RoadNetwork& net() const { return *net_; }

 private:
  const RoadNetwork* net_;
  double segment_m_;
  std::vector<int> first_;    // per lane: its first piece
  std::vector<int> lane_of_;  // per piece
};

// Visit counts read back from one or more coverage CSV files.
struct CoverageCounts {
  std::vector<std::pair<std::string, int>> pieces;  // (lane id, piece) per row, merged
  std::vector<std::int64_t> visits;                 // per entry of `pieces`
  std::int64_t steps = 0;                           // summed over files
  std::int64_t windows = 0;                         // summed over files
  double distinct_per_1k = 0.0;  // window-weighted mean over files (steps-weighted when no
                                 // file has a complete window)
  double segment_m = 10.0;       // of the first file
};

// Counts visits per lane piece and the distinct pieces per step window.
class CoverageTracker {
 public:
  // The network must outlive the tracker.
  explicit CoverageTracker(const RoadNetwork& net, CoverageOptions options = {});

  // Records one env step at `pose` (the ego's footprint centre and heading).
  void observe(const Pose2& pose);
  // Closes the episode in progress (the steps observed since the last call), if it has steps:
  // its distinct pieces and steps join episode_reach() and episode_steps().
  void end_episode();
  // Continues from earlier counts (a resumed run's coverage file): their visits, steps and
  // completed windows join this tracker's; new windows start at the next observed step.
  void restore(const CoverageCounts& counts);

  // Env steps observed (restored ones included).
  std::int64_t steps() const { return steps_; }
  // Visits per piece (steps spent on it), indexed like LaneSegments.
  const std::vector<std::int64_t>& visits() const { return visits_; }
  // Distinct pieces of each completed window observed by this tracker, oldest first.
  const std::vector<int>& window_scores() const { return window_scores_; }
  // The distinct-segments-per-window measure defined at the top of this file (0 before the
  // first step).
  double distinct_per_window() const;
  // Distinct pieces and steps of each closed episode, oldest first.
  const std::vector<int>& episode_reach() const { return episode_reach_; }
  const std::vector<int>& episode_steps() const { return episode_steps_; }
  // Pieces visited at least once.
  int segments_visited() const;
  // segments_visited() / all pieces of the town.
  double fraction_visited() const;
  const LaneSegments& segments() const { return segments_; }
  const CoverageOptions& options() const { return options_; }

  // Writes a CSV (header `lane,piece,visits`, one row per visited piece, preceded by one
  // `# key=value ...` summary line with steps, windows, distinct_per_1k, fraction_visited and
  // segment_m) atomically; throws IoError when it cannot.
  void write_csv(const std::filesystem::path& path) const;

 private:
  LaneSegments segments_;
  CoverageOptions options_;
  std::vector<std::int64_t> visits_;
  std::vector<int> window_scores_;
  std::vector<std::int64_t> last_window_;  // per piece: the last window that visited it
  int current_distinct_ = 0;
  std::int64_t steps_ = 0;
  std::int64_t session_steps_ = 0;  // steps observed here (window boundaries count from 0)
  std::int64_t restored_windows_ = 0;
  double restored_window_sum_ = 0.0;
  double restored_partial_ = 0.0;           // measure of restored counts without a complete window
  std::vector<std::int64_t> last_episode_;  // per piece: the last episode that visited it
  std::int64_t episode_ = 0;                // index of the episode in progress
  int episode_distinct_ = 0;
  int episode_step_count_ = 0;
  std::vector<int> episode_reach_;
  std::vector<int> episode_steps_;
};

// Reads and merges coverage CSV files (visits of the same piece add up). Throws IoError when a
// file is missing or a row is malformed, naming the file and line.
CoverageCounts read_coverage_csv(const std::vector<std::filesystem::path>& files);

// Draws the town's lanes coloured by visit count (log scale; unvisited pieces grey) with a
// colour bar and `title` on top, to a PNG. Pieces in `counts` whose lane is not in the network
// are ignored. Throws IoError when the file cannot be written.
void draw_coverage(const RoadNetwork& net, const CoverageCounts& counts,
                   const std::filesystem::path& png_path, const std::string& title,
                   double pixels_per_m = 2.0);

}  // namespace indrive::env
