// End-to-end smoke runs of the in-process trainer on the real environment (tiny preset, town01):
// a short reward-free pretraining with each intrinsic method, a checkpoint reload, and a short
// lane-following finetune from the disag checkpoint.
//
// Thresholds (seeds fixed by run.seed = 0):
//   - every logged metric is finite and no update produced a non-finite metric;
//   - the world model's reconstruction loss falls: mean of the last quarter of the metrics lines
//     <= kFallRatio x mean of the first quarter (pretraining), and likewise the reward head's
//     loss in finetuning;
//   - the intrinsic module's loss falls too, more loosely (<= kIntrinsicFallRatio);
//   - the intrinsic reward (expl/reward) is finite and not identically zero;
//   - a reload gives bitwise-identical parameters and the same counters, and training continues
//     the counters (env steps and updates keep rising, metrics.jsonl continues past them);
//   - finetuning leaves the world model and the intrinsic module bitwise unchanged.
#include "indrive/local/local_run.h"

#include <gtest/gtest.h>
#include <omp.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstring>
#include <fstream>
#include <nlohmann/json.hpp>
#include <opencv2/videoio.hpp>
#include <sstream>

#include "indrive/basics/episode_csv.h"
#include "indrive/basics/run_dir.h"
#include "testing.h"

namespace indrive::local {
namespace {

namespace fs = std::filesystem;

constexpr std::int64_t kPretrainSteps = 1500;
constexpr double kFallRatio = 0.8;
// The intrinsic modules chase targets that move while the world model learns, so their losses
// fall more slowly (measured: icm 0.88, rnd 0.32, disag 0.86 of the first quarter).
constexpr double kIntrinsicFallRatio = 0.95;

// One OpenMP thread: on a shared two-core machine the tiny model's parallel regions cost more in
// synchronisation than they save (measured about 20x slower updates under load).
[[maybe_unused]] const bool kOneThread = [] {
  omp_set_num_threads(1);
  return true;
}();

service::ServiceConfig make_config(const fs::path& run_dir, std::vector<std::string> overrides) {
  std::vector<std::string> all = {"run.seed=0",
                                  "env.town=town01",
                                  "env.densities=5",
                                  "env.time_limit_steps=300",
                                  "agent.replay.prefill=300",
                                  "learner.replay_ratio=16",
                                  "learner.snapshot_every=5",
                                  "learner.log_interval_s=0.1",
                                  "learner.checkpoint_minutes=60"};
  all.insert(all.end(), overrides.begin(), overrides.end());
  return service::ServiceConfig::resolve(
      {.config_file = testing::source_path("deploy/configs/smoke.yaml"),
       .run_dir = run_dir,
       .overrides = all});
}

std::vector<nlohmann::json> read_metrics(const fs::path& run_dir) {
  std::vector<nlohmann::json> lines;
  std::ifstream in(run_dir / "metrics.jsonl");
  for (std::string line; std::getline(in, line);) {
    if (!line.empty()) lines.push_back(nlohmann::json::parse(line));
  }
  return lines;
}

// Values of `key` in the lines that have it, in order.
std::vector<double> column(const std::vector<nlohmann::json>& lines, const std::string& key) {
  std::vector<double> values;
  for (const auto& line : lines) {
    if (line.contains(key)) values.push_back(line[key].get<double>());
  }
  return values;
}

// Means of the first and the last quarter of a series.
std::pair<double, double> quarter_means(const std::vector<double>& values) {
  const std::size_t quarter = std::max<std::size_t>(1, values.size() / 4);
  double first = 0.0, last = 0.0;
  for (std::size_t i = 0; i < quarter; ++i) {
    first += values[i];
    last += values[values.size() - 1 - i];
  }
  return {first / quarter, last / quarter};
}

void expect_all_finite(const std::vector<nlohmann::json>& lines) {
  for (const auto& line : lines) {
    EXPECT_EQ(line.value("non_finite_metrics", -1), 0) << line.dump();
    for (const auto& [key, value] : line.items()) {
      if (value.is_number()) {
        EXPECT_TRUE(std::isfinite(value.get<double>())) << key;
      }
    }
  }
}

void expect_falls(const std::vector<nlohmann::json>& lines, const std::string& key,
                  double ratio = kFallRatio) {
  const auto values = column(lines, key);
  ASSERT_GE(values.size(), 8u) << "too few metrics lines with " << key;
  const auto [first, last] = quarter_means(values);
  EXPECT_LE(last, ratio * first) << key << ": first quarter " << first << ", last " << last;
  std::printf("%s: first-quarter mean %.4g, last-quarter mean %.4g over %zu lines\n", key.c_str(),
              first, last, values.size());
}

// Every parameter value of the given groups, concatenated.
std::vector<float> parameters(const std::vector<nn::ParamGroup*>& groups) {
  std::vector<float> values;
  for (const nn::ParamGroup* group : groups) {
    for (const auto& param : group->params()) {
      values.insert(values.end(), param->value().begin(), param->value().end());
    }
  }
  return values;
}

bool bitwise_equal(const std::vector<float>& a, const std::vector<float>& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(float)) == 0;
}

// Pretrains with `method` and checks learning; returns the run directory's metrics.
std::vector<nlohmann::json> pretrain(const fs::path& run_dir, const std::string& method) {
  const auto config =
      make_config(run_dir, {"agent.intrinsic.method=" + method,
                            "run.budget_env_steps=" + std::to_string(kPretrainSteps)});
  std::atomic<bool> stop{false};
  LocalRun run(config);
  run.train(stop);
  EXPECT_EQ(run.env_steps(), kPretrainSteps);
  EXPECT_GT(run.updates(), 0);
  EXPECT_GT(run.coverage().segments_visited(), 0);
  EXPECT_TRUE(fs::exists(run_dir / "coverage.csv"));
  const auto lines = read_metrics(run_dir);
  expect_all_finite(lines);
  expect_falls(lines, "wm/recon");
  expect_falls(lines, "intrinsic/loss", kIntrinsicFallRatio);
  const auto rewards = column(lines, "expl/reward");
  EXPECT_FALSE(rewards.empty());
  double magnitude = 0.0;
  for (const double r : rewards) magnitude += std::abs(r);
  EXPECT_GT(magnitude, 0.0) << "the intrinsic reward is identically zero";
  return lines;
}

TEST(LocalRunSmokeTest, PretrainWithIcmLearns) {
  testing::TempDir dir;
  pretrain(dir.path() / "icm", "icm");
}

TEST(LocalRunSmokeTest, PretrainWithRndLearns) {
  testing::TempDir dir;
  pretrain(dir.path() / "rnd", "rnd");
}

TEST(LocalRunSmokeTest, PretrainWithDisagResumesAndFinetunesLaneFollowing) {
  testing::TempDir dir;
  const fs::path pre_dir = dir.path() / "disag";
  pretrain(pre_dir, "disag");

  // Reload: bitwise-identical parameters and the same counters.
  std::vector<float> saved;
  std::int64_t saved_updates = 0;
  {
    const auto config =
        make_config(pre_dir, {"run.budget_env_steps=" + std::to_string(kPretrainSteps)});
    LocalRun reloaded(config);
    EXPECT_EQ(reloaded.env_steps(), kPretrainSteps);
    saved_updates = reloaded.updates();
    EXPECT_GT(saved_updates, 0);
    saved = parameters(reloaded.agent().groups());
  }
  {
    // The checkpoint the first run wrote holds the same parameters as a second reload.
    const auto config =
        make_config(pre_dir, {"run.budget_env_steps=" + std::to_string(kPretrainSteps)});
    LocalRun again(config);
    EXPECT_TRUE(bitwise_equal(parameters(again.agent().groups()), saved));
  }
  // Training continues the counters and the replay: the checkpoint holds the replay, so the
  // resumed run trains from its first step (no second prefill) and the whole run keeps the
  // replay ratio, 16 replayed steps per env step, to the update.
  {
    const auto config =
        make_config(pre_dir, {"run.budget_env_steps=" + std::to_string(kPretrainSteps + 300)});
    LocalRun resumed(config);
    std::atomic<bool> stop{false};
    resumed.train(stop);
    EXPECT_EQ(resumed.env_steps(), kPretrainSteps + 300);
    const auto& replay = config.agent().replay;
    EXPECT_EQ(resumed.updates(), (kPretrainSteps + 300) * 16 / (replay.batch * replay.length));
    EXPECT_GT(resumed.updates(), saved_updates);
    const auto lines = read_metrics(pre_dir);
    ASSERT_FALSE(lines.empty());
    EXPECT_EQ(lines.back()["env_steps"].get<std::int64_t>(), kPretrainSteps + 300);
    EXPECT_EQ(lines.back()["learner_epoch"].get<std::int64_t>(), 2);
    for (std::size_t i = 1; i < lines.size(); ++i) {
      EXPECT_GE(lines[i]["env_steps"].get<std::int64_t>(),
                lines[i - 1]["env_steps"].get<std::int64_t>());
    }
    // Every training episode of both sessions is a row of train-episodes.csv, numbered on
    // across the resume.
    const auto episodes = read_episode_csv(pre_dir / "train-episodes.csv");
    ASSERT_GE(episodes.size(), 2u);
    for (std::size_t i = 0; i < episodes.size(); ++i) {
      EXPECT_EQ(episodes[i].episode, static_cast<int>(i));
      EXPECT_EQ(episodes[i].method, "disag");
      EXPECT_EQ(episodes[i].eval_kind, "training");
      EXPECT_EQ(episodes[i].task, "exploration");
    }
  }

  // Finetune lane following on the straight route from the newest disag checkpoint.
  const auto checkpoints = CheckpointFiles(pre_dir / "checkpoints", 100).newest();
  ASSERT_TRUE(checkpoints.has_value());
  const fs::path ft_dir = dir.path() / "finetune";
  const auto ft_config = make_config(
      ft_dir, {"agent.phase=finetune", "agent.task=lane_following", "env.route=straight",
               "agent.replay.prefill=200", "run.budget_env_steps=1200",
               "learner.init_checkpoint=" + checkpoints->string()});
  LocalRun finetune(ft_config);
  auto& agent = finetune.agent();
  const auto wm_before = parameters({&agent.world_model().params()});
  const auto intrinsic_before = parameters(agent.intrinsic().groups());
  std::atomic<bool> stop{false};
  finetune.train(stop);
  EXPECT_GT(finetune.updates(), 0);
  EXPECT_TRUE(bitwise_equal(parameters({&agent.world_model().params()}), wm_before))
      << "finetuning changed the world model";
  EXPECT_TRUE(bitwise_equal(parameters(agent.intrinsic().groups()), intrinsic_before))
      << "finetuning changed the intrinsic module";
  const auto lines = read_metrics(ft_dir);
  expect_all_finite(lines);
  expect_falls(lines, "wm/reward");
  EXPECT_FALSE(column(lines, "task/critic_loss").empty());
  // The task's episodes are recorded with their route, verdict and return.
  const auto episodes = read_episode_csv(ft_dir / "train-episodes.csv");
  ASSERT_FALSE(episodes.empty());
  for (const EpisodeRecord& e : episodes) {
    EXPECT_EQ(e.task, "lane_following");
    EXPECT_EQ(e.route, "straight");
    EXPECT_EQ(e.success, e.failure_reason.empty()) << e.failure_reason;
    EXPECT_GE(e.route_completion, 0.0);
    EXPECT_LE(e.route_completion, 1.0);
  }
}

// Metrics lines come at each multiple of learner.log_every_env_steps as well as by time, so a
// fast run (a random policy steps thousands of times a second) has a curve over env steps
// comparable with a slow one.
TEST(LocalRunTest, ARunLogsAMetricsLineEveryLogStepsEvenWhenFast) {
  testing::TempDir dir;
  const auto config = make_config(
      dir.path() / "random", {"local.random=true", "run.budget_env_steps=700",
                              "learner.log_interval_s=3600", "learner.log_every_env_steps=200"});
  std::atomic<bool> stop{false};
  LocalRun run(config);
  run.train(stop);
  std::vector<std::int64_t> steps;
  for (const auto& line : read_metrics(dir.path() / "random")) {
    steps.push_back(line["env_steps"].get<std::int64_t>());
  }
  // The trainer steps in slices of 16: each line comes within one slice of its multiple, and
  // the run's end adds one line.
  ASSERT_EQ(steps.size(), 4u);
  for (int k = 0; k < 3; ++k) {
    EXPECT_GE(steps[k], 200 * (k + 1));
    EXPECT_LT(steps[k], 200 * (k + 1) + 16);
  }
  EXPECT_EQ(steps[3], 700);

  // Reach per episode (coverage.h): every closed episode visits at least its spawn piece and
  // no more pieces than it took steps; the last line's mean over the last 20 matches them.
  const auto& reach = run.coverage().episode_reach();
  const auto& lengths = run.coverage().episode_steps();
  ASSERT_GE(reach.size(), 2u) << "a random policy ends episodes within 700 steps";
  ASSERT_EQ(reach.size(), lengths.size());
  int total = 0;
  for (std::size_t i = 0; i < reach.size(); ++i) {
    EXPECT_GE(reach[i], 1) << "episode " << i;
    EXPECT_LE(reach[i], lengths[i]) << "episode " << i;
    total += lengths[i];
  }
  EXPECT_LE(total, 700);
  const std::size_t from = reach.size() > 20 ? reach.size() - 20 : 0;
  double mean = 0.0;
  for (std::size_t i = from; i < reach.size(); ++i) mean += reach[i];
  mean /= static_cast<double>(reach.size() - from);
  const auto last = read_metrics(dir.path() / "random").back();
  EXPECT_NEAR(last.value("episode_reach_last20", -1.0), mean, 1e-9) << last.dump();

  // Each finished training episode is a row of train-episodes.csv: free driving (no route),
  // its steps within the run's.
  const auto episodes = read_episode_csv(dir.path() / "random" / "train-episodes.csv");
  ASSERT_GE(episodes.size(), reach.size());
  ASSERT_LE(episodes.size(), reach.size() + 1);
  int recorded = 0;
  for (const EpisodeRecord& e : episodes) {
    EXPECT_EQ(e.method, "random");
    EXPECT_EQ(e.eval_kind, "training");
    EXPECT_EQ(e.route, "");
    EXPECT_GT(e.steps, 0);
    recorded += e.steps;
  }
  EXPECT_LE(recorded, 700);
}

// One column of a CSV file with a header row, by name (cells hold no commas here).
std::vector<std::string> csv_column(const fs::path& file, const std::string& name) {
  std::ifstream in(file);
  std::vector<std::vector<std::string>> rows;
  for (std::string line; std::getline(in, line);) {
    std::vector<std::string> cells;
    std::stringstream row(line);
    for (std::string cell; std::getline(row, cell, ',');) cells.push_back(cell);
    rows.push_back(std::move(cells));
  }
  std::vector<std::string> column;
  if (rows.empty()) return column;
  const auto at = std::find(rows[0].begin(), rows[0].end(), name);
  if (at == rows[0].end()) return column;
  const std::size_t index = static_cast<std::size_t>(at - rows[0].begin());
  for (std::size_t r = 1; r < rows.size(); ++r) {
    column.push_back(index < rows[r].size() ? rows[r][index] : "");
  }
  return column;
}

// The local evaluation records the first eval.video_episodes episodes of each density, as the
// evaluator does: one frame after the reset and after every step, then a second (10 frames) of
// the last frame.
TEST(LocalRunTest, EvaluationRecordsTheFirstEpisodesOfEachDensityAsVideo) {
  testing::TempDir dir;
  const fs::path run_dir = dir.path() / "random";
  const auto config = make_config(run_dir, {"local.random=true", "eval.densities=5",
                                            "eval.video_episodes=1", "env.route=straight"});
  std::atomic<bool> stop{false};
  const EvaluationSummary summary = evaluate_locally(config, "straight", 2, stop);
  ASSERT_EQ(summary.episodes, 2);

  const auto steps_column = csv_column(run_dir / "eval" / "local-town01-straight.csv", "steps");
  ASSERT_EQ(steps_column.size(), 2u);
  const int steps = std::stoi(steps_column[0]);

  const fs::path video = run_dir / "videos" / "eval-town01-straight-5-0.mp4";
  ASSERT_TRUE(fs::exists(video));
  EXPECT_FALSE(fs::exists(run_dir / "videos" / "eval-town01-straight-5-1.mp4"));
  cv::VideoCapture capture(video.string(), cv::CAP_FFMPEG);
  ASSERT_TRUE(capture.isOpened());
  int frames = 0;
  cv::Mat frame;
  while (capture.read(frame)) ++frames;
  EXPECT_EQ(frames, 1 + steps + 10);
}

// The local evaluation, like the evaluator, ends an episode at the route's step budget
// (eval.budget_speed_mps and eval.budget_slack), not at the training time limit
// env.time_limit_steps: with a 10-step env limit, random episodes still run until they fail or
// the budget runs out.
TEST(LocalRunTest, EvaluationEndsEpisodesAtTheRouteBudgetNotTheEnvTimeLimit) {
  testing::TempDir dir;
  const fs::path run_dir = dir.path() / "random";
  const auto config =
      make_config(run_dir, {"local.random=true", "eval.densities=5", "env.time_limit_steps=10",
                            "eval.budget_speed_mps=30", "env.route=straight"});
  std::atomic<bool> stop{false};
  ASSERT_EQ(evaluate_locally(config, "straight", 3, stop).episodes, 3);
  const fs::path csv = run_dir / "eval" / "local-town01-straight.csv";
  const auto steps = csv_column(csv, "steps");
  const auto reasons = csv_column(csv, "failure_reason");
  ASSERT_EQ(steps.size(), 3u);
  ASSERT_EQ(reasons.size(), 3u);
  // town01's straight, 198 m (the road less its 20 m set-back), at 30 m/s (3 m per 0.1 s step)
  // with 1.5x slack: 99 steps.
  constexpr int kBudget = 99;
  for (std::size_t i = 0; i < steps.size(); ++i) {
    EXPECT_GT(std::stoi(steps[i]), 10) << "episode " << i << " ended by " << reasons[i];
    EXPECT_LE(std::stoi(steps[i]), kBudget) << "episode " << i;
    if (reasons[i] == "time_limit") {
      EXPECT_EQ(std::stoi(steps[i]), kBudget) << "episode " << i;
    }
  }
}

// A finetune without a checkpoint to start from is refused with a clear error, before SUMO
// starts.
TEST(LocalRunTest, FinetuneWithoutACheckpointIsRefused) {
  testing::TempDir dir;
  const auto config =
      make_config(dir.path() / "orphan", {"agent.phase=finetune", "env.route=straight"});
  EXPECT_THROW(LocalRun{config}, LocalRunError);
}

// A run starts as the learner does (learner::start_run): a newest checkpoint cut short by a
// crash is set aside, and the run goes on from the one before it.
TEST(LocalRunTest, AResumedRunSkipsADamagedNewestCheckpoint) {
  testing::TempDir dir;
  const fs::path run_dir = dir.path() / "random";
  std::atomic<bool> stop{false};
  {
    const auto config = make_config(run_dir, {"local.random=true", "run.budget_env_steps=300"});
    LocalRun run(config);  // keeps a reference to its config
    run.train(stop);
  }
  const fs::path intact = CheckpointFiles(run_dir / "checkpoints", 10).newest().value();
  const fs::path newer = run_dir / "checkpoints" / "ckpt-000000000007.bin";
  const auto bytes = read_file(intact);
  atomic_write(newer, std::span<const std::uint8_t>(bytes.data(), bytes.size() / 2));

  const auto config = make_config(run_dir, {"local.random=true", "run.budget_env_steps=400"});
  LocalRun resumed(config);
  EXPECT_EQ(resumed.env_steps(), 300);
  EXPECT_FALSE(fs::exists(newer));
  EXPECT_TRUE(fs::exists(newer.string() + ".damaged"));
}

}  // namespace
}  // namespace indrive::local
