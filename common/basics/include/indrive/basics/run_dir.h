// The run directory (docs/architecture.md, section 7) and crash-safe file writing.
//
//   runs/<run_id>/config.yaml      fully resolved configuration
//   runs/<run_id>/checkpoints/     atomic writes, newest N kept
//   runs/<run_id>/metrics.jsonl    one JSON object per log interval
//   runs/<run_id>/eval/*.csv       one row per evaluated episode
//   runs/<run_id>/train-episodes.csv   one row per finished training episode (same columns)
//   runs/<run_id>/final-snapshot.params   the policy the learner ended the run with
//   runs/<run_id>/report.md, plots/*.png, videos/*.mp4
//
//   RunDir run = RunDir::open_or_create("runs", "pretrain-disag-s0");
//   atomic_write(run.checkpoints() / "ckpt-000100.bin", bytes);
//   MetricsLog metrics(run.metrics_path());
//   metrics.write({{"env_steps", 1000}, {"wm_loss", 2.5}});
#pragma once

#include <cstdint>
#include <deque>
#include <filesystem>
#include <fstream>
#include <nlohmann/json_fwd.hpp>
#include <optional>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

namespace indrive {

// A file could not be read or written; the message names the path and the reason.
class IoError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Writes `bytes` to `path` so that a crash at any moment leaves either the old file or the
// complete new one, never a partial file: write a temporary sibling, fsync it, rename it over
// `path`, fsync the directory.
void atomic_write(const std::filesystem::path& path, std::span<const std::uint8_t> bytes);
void atomic_write(const std::filesystem::path& path, const std::string& text);

// The policy a run's learner ended the run with (a snapshot file), in the run directory
// `run_dir`: what evaluators and `--snapshot DIR` look for after the learner has gone.
inline std::filesystem::path final_snapshot_path(const std::filesystem::path& run_dir) {
  return run_dir / "final-snapshot.params";
}

// Reads a whole file; throws IoError naming the path if it cannot.
std::vector<std::uint8_t> read_file(const std::filesystem::path& path);

// A run's directory with its fixed layout.
class RunDir {
 public:
  // Creates runs_root/run_id and its subfolders if missing. A run id may hold letters, digits,
  // '-', '_' and '.'; anything else throws std::invalid_argument naming the bad character.
  static RunDir open_or_create(const std::filesystem::path& runs_root, const std::string& run_id);

  const std::string& run_id() const { return run_id_; }
  const std::filesystem::path& path() const { return path_; }
  std::filesystem::path config_path() const { return path_ / "config.yaml"; }
  std::filesystem::path metrics_path() const { return path_ / "metrics.jsonl"; }
  std::filesystem::path checkpoints() const { return path_ / "checkpoints"; }
  std::filesystem::path eval() const { return path_ / "eval"; }
  std::filesystem::path train_episodes_path() const { return path_ / "train-episodes.csv"; }
  std::filesystem::path plots() const { return path_ / "plots"; }
  std::filesystem::path videos() const { return path_ / "videos"; }
  std::filesystem::path report_path() const { return path_ / "report.md"; }

 private:
  RunDir(std::string run_id, std::filesystem::path path)
      : run_id_(std::move(run_id)), path_(std::move(path)) {}
  std::string run_id_;
  std::filesystem::path path_;
};

// Checkpoints named ckpt-<12-digit counter>.bin in one folder, newest `keep` retained.
class CheckpointFiles {
 public:
  CheckpointFiles(std::filesystem::path folder, int keep);
  // Writes a checkpoint atomically for `counter` (e.g. the update count), then deletes all
  // but the newest `keep`. Returns its path.
  // Throws IoError when the file cannot be written (e.g. the disk is full); then the older
  // checkpoints are untouched and no temporary file is left.
  std::filesystem::path save(std::uint64_t counter, std::span<const std::uint8_t> bytes);
  // The path save(counter, ...) writes.
  std::filesystem::path path(std::uint64_t counter) const;
  // The newest complete checkpoint, if any (temporary files of an interrupted write are
  // ignored).
  std::optional<std::filesystem::path> newest() const;
  // All checkpoints, oldest first.
  std::vector<std::filesystem::path> list() const;

 private:
  std::filesystem::path folder_;
  int keep_;
};

// Appends one JSON object per line to metrics.jsonl, flushed per line so a crash loses at
// most the line being written. Each line gets "time" (Unix seconds) if it lacks one.
class MetricsLog {
 public:
  explicit MetricsLog(const std::filesystem::path& path);
  void write(const nlohmann::json& record);

 private:
  std::filesystem::path path_;
  std::ofstream out_;
};

// Whether a counter moved past a multiple of `every` between `before` and `now` (false when
// `every` <= 0): the learner and the local trainer write a metrics line at each multiple of
// learner.log_every_env_steps as well as by time.
bool passed_multiple(std::int64_t before, std::int64_t now, std::int64_t every);

// Length and reach (distinct lane segments driven from spawn to end, envserver/coverage.h) of
// training episodes, for metrics.jsonl: the learner (from the actors' EpisodeResults) and the
// local trainer (from its coverage tracker) log the same keys with the same meaning.
//
//   EpisodeStats episodes;
//   episodes.add(/*steps=*/240, /*reach=*/9);   // per finished episode
//   episodes.write(record);                    // per metrics line
class EpisodeStats {
 public:
  // `window`: the recent episodes behind the *_last<window> keys (20 in every run so far).
  explicit EpisodeStats(std::size_t window = 20);

  void add(std::int64_t steps, std::int64_t reach);

  // Adds episode_length and episode_reach (means over the episodes added since the last call;
  // left out when there were none) and episode_length_last20 / episode_reach_last20 (means over
  // the newest `window` episodes ever added; left out before the first) to `record`.
  void write(nlohmann::json& record);

 private:
  std::size_t window_;
  std::deque<std::pair<std::int64_t, std::int64_t>> recent_;  // (steps, reach), newest last
  std::int64_t interval_episodes_ = 0, interval_steps_ = 0, interval_reach_ = 0;
};

}  // namespace indrive
