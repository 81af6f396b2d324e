// Evaluation results on disk: one CSV row per episode (runs/<id>/eval/*.csv).
//
// Evaluators append rows; `indrive report` reads the files of one or many runs. The header
// line names the columns, so files stay readable by spreadsheets and pandas alike.
#pragma once

#include <filesystem>
#include <fstream>
#include <stdexcept>
#include <string>
#include <vector>

namespace indrive {

// One evaluated episode.
struct EpisodeRecord {
  std::string run_id;     // the training run the policy came from
  std::string method;     // disag | icm | rnd | dreamer | random | oracle | ...
  std::string eval_kind;  // zero_shot | few_shot
  std::string task;       // exploration | lane_following | collision_avoidance
  int train_seed = 0;     // seed of the training run (tables average over these)
  long long policy_version = 0;
  std::string town;   // town01, town02, or a user map's name
  std::string route;  // straight | right_loop | left_loop | two_turn
  int density = 0;    // 5 | 10 | 20 traffic vehicles within 150 m
  int traffic_seed = 0;
  int spawn_seed = 0;
  int episode = 0;  // index within its (town, route, density) cell
  bool success = false;
  std::string failure_reason;  // empty on success: collision, lane_invasion, off_road, ...
  int steps = 0;
  double route_completion = 0.0;    // fraction of the route driven, 0..1
  double episode_return = 0.0;      // task return; 0 in zero-shot evaluation
  std::string protocol = "strict";  // the rules that judged it: strict | indrive_code
  int lane_invasions = 0;           // entries into the lane-invasion condition (terminal under
                                    // strict, so 0 or 1 there; counted under indrive_code)
};

// A results file could not be read; the message names the file, line and column.
class CsvError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// The header line every results file starts with.
const std::string& episode_csv_header();

// Appends records to a CSV file, writing the header first if the file is new or empty.
// Each row is flushed, so a crash loses at most the row being written; a partial last line
// that such a crash left is cut off when the file is opened again, so that the rows appended
// after it stay readable.
class EpisodeCsvWriter {
 public:
  explicit EpisodeCsvWriter(const std::filesystem::path& path);
  void write(const EpisodeRecord& record);
  // Data rows in the file: those it held when opened and those written since.
  long long rows() const { return rows_; }

 private:
  std::filesystem::path path_;
  std::ofstream out_;
  long long rows_ = 0;
  bool v1_ = false;  // the file has episode_csv_header_v1()
};

// The header of files written before the protocol and lane_invasions columns: such files are
// read as strict evaluations, lane_invasions 1 where lane_invasion ended the episode. A writer
// appending to one (a resumed run's) keeps its columns and refuses rows of another protocol.
const std::string& episode_csv_header_v1();

// Reads every record of one file. Throws CsvError for a wrong header, a wrong number of
// fields or a value that does not parse.
std::vector<EpisodeRecord> read_episode_csv(const std::filesystem::path& path);

}  // namespace indrive
