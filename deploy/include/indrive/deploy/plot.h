// Line plots to PNG for learning curves (losses, intrinsic reward, SR over env steps), drawn
// by PLplot (line_plot.cc).
//
//   LinePlot plot("World-model loss", "env steps", "loss");
//   plot.add_series("disag", xs, ys);
//   plot.save("runs/x/plots/wm_loss.png");
#pragma once

#include <cstdint>
#include <filesystem>
#include <map>
#include <nlohmann/json_fwd.hpp>
#include <opencv2/core.hpp>
#include <optional>
#include <string>
#include <vector>

namespace indrive::deploy {

class LinePlot {
 public:
  LinePlot(std::string title, std::string x_label, std::string y_label);

  // Adds a named series; x and y must have the same length. Non-finite points are skipped.
  void add_series(const std::string& name, std::vector<double> x, std::vector<double> y);
  // Adds a named series with a shaded band from `low` to `high` around it (e.g. the spread of
  // training seeds around their mean); all four must have the same length.
  void add_series(const std::string& name, std::vector<double> x, std::vector<double> y,
                  std::vector<double> low, std::vector<double> high);
  // Smooths every series of 50 points or more with an exponential moving average of this
  // weight (0: none) when drawing; the raw series is drawn faintly behind it. Shorter series
  // are drawn unsmoothed.
  void set_smoothing(double weight) { smoothing_ = weight; }
  bool empty() const { return series_.empty(); }

  // Renders the plot (BGR, width x height).
  cv::Mat render(int width = 800, int height = 480) const;
  // Renders and writes a PNG; throws IoError naming the path if it cannot.
  void save(const std::filesystem::path& path, int width = 800, int height = 480) const;

 private:
  struct Range;  // the data's extent, padded
  void draw_axes(const Range& range) const;
  void draw_series(const Range& range) const;
  struct Series {
    std::string name;
    std::vector<double> x;
    std::vector<double> y;
    std::vector<double> low, high;  // empty: no band
  };
  std::string title_;
  std::string x_label_;
  std::string y_label_;
  std::vector<Series> series_;
  double smoothing_ = 0.0;
};

// "Nice" tick positions (1, 2, 5 x 10^k steps) covering [low, high], about `count` of them.
std::vector<double> nice_ticks(double low, double high, int count);

// The numeric keys of metrics.jsonl as (x, y) columns against `x_key`; lines without x are
// skipped, a cut last line (a crashed run) is ignored, any other bad line throws IoError.
using MetricColumns = std::map<std::string, std::pair<std::vector<double>, std::vector<double>>>;
MetricColumns read_metric_columns(const std::filesystem::path& metrics_jsonl,
                                  const std::string& x_key = "env_steps");

// A metrics.jsonl that a running process appends to, read again and again at the cost of what
// was appended: each update() parses only the complete lines added since the last (a line still
// being written waits for its newline). The same rules as read_metric_columns otherwise; a file
// that shrank (a new run in the same folder) is read again from its start.
class MetricsFollower {
 public:
  explicit MetricsFollower(std::filesystem::path metrics_jsonl, std::string x_key = "env_steps");
  // Reads what was appended; a missing file is no error (no lines yet). Throws IoError for a
  // corrupt line. With `final`, a last line without its newline is read too when it parses.
  const MetricColumns& update(bool final = false);
  const MetricColumns& columns() const { return columns_; }

 private:
  void add_line(const std::string& line, bool last_of_file);
  std::filesystem::path path_;
  std::string x_key_;
  std::uintmax_t offset_ = 0;
  int line_number_ = 0;
  MetricColumns columns_;
};

// Writes one PNG per numeric key of metrics.jsonl (other than the x key) into `out_dir`,
// against `x_key` (default env_steps). Returns the files written.
std::vector<std::filesystem::path> plot_metrics(const std::filesystem::path& metrics_jsonl,
                                                const std::filesystem::path& out_dir,
                                                const std::string& x_key = "env_steps");

// Several runs of one configuration (e.g. its training seeds) reduced to one curve: every
// run's (x, y) series, sorted by x, is interpolated linearly at `points` x values spread evenly
// over the x range that all runs cover; `mean` is their average there, `low` and `high` the
// smallest and largest run. Throws std::invalid_argument when a run is empty or the runs share
// no x range.
struct MeanBand {
  std::vector<double> x, mean, low, high;
};
MeanBand mean_band(const std::vector<std::pair<std::vector<double>, std::vector<double>>>& runs,
                   int points = 200);

// Runs drawn as one curve by plot_compare: one run as its own line, several as their mean with
// a min-max band.
struct CompareGroup {
  std::string label;
  std::vector<std::filesystem::path> runs;
};
// One run as its own group, labelled by its folder name.
CompareGroup single_run_group(const std::filesystem::path& run);
// Parses "LABEL=RUN[,RUN...]" (the command line's --group); throws std::invalid_argument
// saying what the form is when the label or the runs are missing.
CompareGroup parse_compare_group(const std::string& spec);

// Where a line of a compare plot ends: its last x, the (mean) value there and, for a group,
// its lowest and highest run there (both the value for a single run).
struct CompareEnd {
  std::string label;
  double x = 0.0, y = 0.0, low = 0.0, high = 0.0;
};

// One PNG comparing `metric` across groups of runs, e.g. the coverage of random-policy runs
// against disag runs over several seeds; a group of one run is its line, a group of several
// is labelled "LABEL (mean of N, band min-max)" and drawn with the band between its lowest and
// highest run. `smoothing` as LinePlot's (none by default: a running average lags a cumulative
// measure). A run without the metric is an IoError naming it. Returns where each line ends, so
// that the figures can be quoted beside the picture.
std::vector<CompareEnd> plot_compare(const std::vector<CompareGroup>& groups,
                                     const std::string& metric,
                                     const std::filesystem::path& png_path,
                                     const std::string& x_key = "env_steps",
                                     double smoothing = 0.0);

// A continuous evaluator's learning curve summarised per town: for every env-step count at
// which a snapshot was evaluated, the episodes behind it, their success rate and their mean
// route completion (all evaluators of the run pooled).
struct EvalCurvePoint {
  double env_steps = 0.0;
  int episodes = 0;
  double success_rate = 0.0;      // in [0, 1]
  double route_completion = 0.0;  // mean, in [0, 1]
};
using EvalCurves = std::map<std::string, std::vector<EvalCurvePoint>>;  // town -> by env steps

// Reads eval/curve-*.csv files (see actor/evaluator.h: curve_csv_header). A cut last line (a
// crashed evaluator) is skipped; any other malformed row throws IoError naming file and line.
EvalCurves read_eval_curves(const std::vector<std::filesystem::path>& files);

// The files of `folder` whose name starts with `prefix` and ends with `suffix`, sorted; none when
// the folder does not exist. E.g. run_files(run / "eval", "curve-", ".csv").
std::vector<std::filesystem::path> run_files(const std::filesystem::path& folder,
                                             const std::string& prefix, const std::string& suffix);

// Writes eval_success_rate.png and eval_route_completion.png (one series per town, against env
// steps) into `out_dir` from <run>/eval/curve-*.csv. Returns the files written; none when the
// run has no learning-curve files.
std::vector<std::filesystem::path> plot_eval_curves(const std::filesystem::path& run_dir,
                                                    const std::filesystem::path& out_dir);

// Draws the coverage map of a run: the training town (env.town of <run>/config.yaml) with its
// lane pieces coloured by visits, from <run>/coverage.csv (indrive-train-local) and
// <run>/coverage/actor-*.csv (training actors), merged; the title states the town, the env
// steps, the distinct lane segments per 1,000 steps and the fraction of the town visited.
// Returns the PNG written, or nullopt when the run has no coverage files. Throws IoError or the
// envserver's MapError when a file or the town cannot be read.
std::optional<std::filesystem::path> plot_coverage(const std::filesystem::path& run_dir,
                                                   const std::filesystem::path& png_path);

}  // namespace indrive::deploy
