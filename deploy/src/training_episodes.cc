#include "indrive/deploy/training_episodes.h"

#include <algorithm>
#include <cstdio>
#include <sstream>
#include <stdexcept>

#include "indrive/envserver/routes.h"

namespace indrive::deploy {
namespace fs = std::filesystem;
namespace {

// The paper's routes in their order, then any other route by name, free driving last.
int route_rank(const std::string& route) {
  for (std::size_t i = 0; i < env::kRouteNames.size(); ++i) {
    if (route == env::kRouteNames[i]) return static_cast<int>(i);
  }
  return route.empty() ? 1000 : 100;
}

std::string fixed(double value, int digits) {
  char text[64];
  std::snprintf(text, sizeof text, "%.*f", digits, value);
  return text;
}

std::string percent(double fraction) { return fixed(100.0 * fraction, 0) + "%"; }

}  // namespace

RunTraining summarize_training(const std::vector<EpisodeRecord>& rows, int last) {
  if (last < 1) throw std::invalid_argument("--last must be at least 1 episode");
  if (rows.empty()) throw std::invalid_argument("no training episodes to summarise");
  std::map<std::string, std::vector<const EpisodeRecord*>> by_route;
  for (const EpisodeRecord& row : rows) by_route[row.route].push_back(&row);
  RunTraining run{.label = rows.front().run_id,
                  .run_id = rows.front().run_id,
                  .method = rows.front().method,
                  .task = rows.front().task,
                  .train_seed = rows.front().train_seed};
  double balanced = 0.0;
  for (const auto& [route, episodes] : by_route) {
    RouteTraining r{.route = route, .episodes = static_cast<int>(episodes.size())};
    r.last = std::min(r.episodes, last);
    for (int i = 0; i < r.episodes; ++i) {
      const EpisodeRecord& e = *episodes[static_cast<std::size_t>(i)];
      r.successes += e.success ? 1 : 0;
      r.mean_return += e.episode_return;
      r.mean_completion += e.route_completion;
      if (!e.success) ++r.failures[e.failure_reason.empty() ? "none" : e.failure_reason];
      if (i >= r.episodes - r.last) {
        r.last_return += e.episode_return;
        r.last_completion += e.route_completion;
      }
    }
    r.mean_return /= r.episodes;
    r.mean_completion /= r.episodes;
    r.last_return /= r.last;
    r.last_completion /= r.last;
    balanced += r.last_return;
    run.episodes += r.episodes;
    run.routes.push_back(std::move(r));
  }
  std::stable_sort(run.routes.begin(), run.routes.end(),
                   [](const RouteTraining& a, const RouteTraining& b) {
                     return route_rank(a.route) < route_rank(b.route);
                   });
  run.balanced_last_return = balanced / static_cast<double>(run.routes.size());
  return run;
}

std::string render_training(const std::vector<RunTraining>& runs, int last) {
  std::ostringstream out;
  const std::string n = std::to_string(last);
  for (const RunTraining& run : runs) {
    out << "## " << run.label << " (" << run.method << ", " << run.task << ", seed "
        << run.train_seed << "): " << run.episodes << " training episodes\n\n";
    out << "| route | episodes | SR | completion | return | last-" << n << " completion | last-"
        << n << " return | failures |\n";
    out << "|---|---|---|---|---|---|---|---|\n";
    for (const RouteTraining& r : run.routes) {
      std::vector<std::pair<std::string, int>> failures(r.failures.begin(), r.failures.end());
      std::stable_sort(failures.begin(), failures.end(),
                       [](const auto& a, const auto& b) { return a.second > b.second; });
      std::string failed;
      for (const auto& [reason, count] : failures) {
        failed += (failed.empty() ? "" : ", ") + reason + " " + std::to_string(count);
      }
      out << "| " << (r.route.empty() ? "(no route)" : r.route) << " | " << r.episodes << " | "
          << percent(static_cast<double>(r.successes) / r.episodes) << " | "
          << percent(r.mean_completion) << " | " << fixed(r.mean_return, 1) << " | "
          << percent(r.last_completion) << " (" << r.last << ") | " << fixed(r.last_return, 1)
          << " | " << (failed.empty() ? "-" : failed) << " |\n";
    }
    out << "\nBalanced over routes (the mean of the routes' last-" << n
        << " returns): " << fixed(run.balanced_last_return, 1) << "\n\n";
  }
  return out.str();
}

std::vector<EpisodeRecord> load_training_episodes(const fs::path& input) {
  const fs::path file = fs::is_directory(input) ? input / "train-episodes.csv" : input;
  if (!fs::is_regular_file(file)) {
    throw CsvError(file.string() +
                   " does not exist: name a run directory of indrive-train-local or "
                   "indrive-learner that has finished training episodes (they write "
                   "<run>/train-episodes.csv since 2026-12-05), or that file");
  }
  auto rows = read_episode_csv(file);
  if (rows.empty()) {
    throw CsvError(file.string() + " holds no training episode yet: the run has finished none");
  }
  return rows;
}

}  // namespace indrive::deploy
