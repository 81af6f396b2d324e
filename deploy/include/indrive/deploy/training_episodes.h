// `indrive episodes`: how training went, per route, from the runs' train-episodes.csv.
//
// A task run draws one of its routes per episode, so its overall return mixes routes of very
// different worth (a completed `straight` earns about 250, a loop left at its first junction
// 10-150); which routes its last episodes happened to draw moves that mean more than the
// policy does. Per route (episodes, SR, mean route completion, mean return, and the same over
// the route's newest N episodes), and balanced over routes (the mean of the routes' last-N
// returns), the figures compare runs fairly.
//
//   indrive episodes runs/finetune-lf-disag-s0 runs/finetune-lf-dreamer-s0 --last 5
#pragma once

#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include "indrive/basics/episode_csv.h"

namespace indrive::deploy {

// One route's training episodes of one run (route "" = free driving, pretraining).
struct RouteTraining {
  std::string route;
  int episodes = 0;
  int successes = 0;
  double mean_return = 0.0;
  double mean_completion = 0.0;  // fraction of the route, 0..1
  int last = 0;                  // episodes behind the last_* figures: min(episodes, N)
  double last_return = 0.0;      // mean return of the route's newest N episodes
  double last_completion = 0.0;
  std::map<std::string, int> failures;  // failure reason -> episodes
};

// One run's training episodes.
struct RunTraining {
  std::string label;  // what the table is headed with: the run directory or file
  std::string run_id, method, task;
  int train_seed = 0;
  int episodes = 0;
  std::vector<RouteTraining> routes;  // the paper's route order first, then others by name
  // Mean over the routes of their last_return: a return measure that the draw of routes does
  // not move.
  double balanced_last_return = 0.0;
};

// Summarises one run's rows (file order = episode order) per route; the last_* figures use
// each route's newest `last` episodes. Throws std::invalid_argument when `rows` is empty or
// `last` < 1.
RunTraining summarize_training(const std::vector<EpisodeRecord>& rows, int last);

// The runs' tables in markdown.
std::string render_training(const std::vector<RunTraining>& runs, int last);

// Reads a run's train-episodes.csv (`input`: the run directory or the file). Throws CsvError
// naming the path and what to do when it is missing or holds no episode.
std::vector<EpisodeRecord> load_training_episodes(const std::filesystem::path& input);

}  // namespace indrive::deploy
