// train-episodes.csv: one row per finished training episode, for indrive-learner (the actors'
// EpisodeResults) and indrive-train-local (its own episodes) alike.
//
//   TrainingEpisodes episodes(run.train_episodes_path(),
//                             {.method = "disag", .task = "exploration", .train_seed = 0});
//   episodes.write(record);  // method, eval_kind, task, seed and episode number filled in
#pragma once

#include <filesystem>
#include <optional>
#include <string>

#include "indrive/basics/episode_csv.h"

namespace indrive::learner {

// What every row of a run carries.
struct TrainingRunLabels {
  std::string method;  // agent::method_label, or "random" for the random baseline
  std::string task;    // agent::task_label
  int train_seed = 0;
};

class TrainingEpisodes {
 public:
  // `log_tag`: the log channel of the process, for the one error a failing file gets.
  TrainingEpisodes(std::filesystem::path path, TrainingRunLabels labels,
                   std::string log_tag = "learner");
  // Writes `row` with the run's labels, eval_kind "training" and the next episode number (a
  // resumed run numbers on from the rows the file holds). The file is opened at the first
  // episode, so a run that only reloads or reports writes none. A failure to open or write is
  // logged once (the next episodes try again, quietly) and does not stop training.
  void write(EpisodeRecord row);
  // Rows written so far, those of earlier sessions included (0 before the first episode).
  long long rows() const { return csv_ ? csv_->rows() : 0; }

 private:
  std::filesystem::path path_;
  TrainingRunLabels labels_;
  std::string log_tag_;
  std::optional<EpisodeCsvWriter> csv_;
  bool failed_ = false;  // a failure was logged
};

}  // namespace indrive::learner
