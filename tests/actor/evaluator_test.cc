// The evaluator end to end, without a learner: a small protocol grid (2 routes x 1 density x
// 2 episodes on both built-in towns) driven by the oracle, every CSV row checked against an
// independent replay of its episode, and the report's cells recomputed by hand from the rows.
// Also: a snapshot file evaluated without DDS, and the evaluator's bad inputs.
#include "indrive/actor/evaluator.h"

#include <gtest/gtest.h>

#include <atomic>
#include <cmath>
#include <fstream>
#include <functional>
#include <map>
#include <thread>

#include "indrive/actor/env_adapter.h"
#include "indrive/actor/eval_protocol_record.h"
#include "indrive/actor/policies.h"
#include "indrive/actor/snapshot_file.h"
#include "indrive/agent/agent.h"
#include "indrive/basics/episode_csv.h"
#include "indrive/dds/participant.h"
#include "indrive/deploy/report.h"
#include "indrive/envserver/env.h"
#include "testing.h"

namespace indrive::actor {
namespace {

using agent::read_snapshot_file;
using agent::SnapshotFile;
using agent::write_snapshot_file;

service::ServiceConfig resolve(const std::filesystem::path& run_dir,
                               std::vector<std::string> overrides) {
  overrides.insert(overrides.begin(), "preset=tiny");
  return service::ServiceConfig::resolve({.run_dir = run_dir, .overrides = overrides});
}

// What the test's own replay of one episode gives.
struct Replay {
  std::uint32_t events = 0;
  int steps = 0;
  double progress_m = 0.0;
  double length_m = 0.0;
};

// Replays an episode with its own env and loop: same seeds, same budget rule, same policy.
Replay replay(env::Env& env, const EpisodeSpec& spec, EpisodePolicy& policy) {
  env::StepResult step = env.reset({.town = spec.town,
                                    .route = spec.route,
                                    .density = spec.density,
                                    .traffic_seed = static_cast<std::uint64_t>(spec.traffic_seed),
                                    .spawn_seed = static_cast<std::uint64_t>(spec.spawn_seed)});
  policy.begin(env, spec);
  const int budget = route_step_budget(env.route()->length_m());
  while (!step.is_last && step.step < budget) step = env.step(policy.act(env, step));
  Replay out{step.events, step.step, step.route_progress_m, env.route()->length_m()};
  if (!step.is_last) out.events |= env::kTimeLimit;
  return out;
}

// Runs one evaluator (scoped: libsumo holds one simulation per process) and returns its rows.
std::vector<EpisodeRecord> evaluate(const service::ServiceConfig& config) {
  Evaluator evaluator(config, 0, 1);
  const std::atomic<bool> stop{false};
  EXPECT_EQ(evaluator.run(stop), 0);
  return read_episode_csv(evaluator.results_file());
}

// [method][{town, route}] -> {episodes, successes}, counted by hand from the rows.
using ByHand =
    std::map<std::string, std::map<std::pair<std::string, std::string>, std::pair<int, int>>>;

// The report's cells, from the same rows: one seed and one density, so SR = successes / n.
void expect_report_matches(const std::vector<EpisodeRecord>& rows, const ByHand& by_hand) {
  const deploy::Report report = deploy::aggregate(rows);
  const deploy::Table& table = report.tables.at({"strict", "zero_shot", "exploration"});
  EXPECT_EQ(table.routes, (std::vector<std::string>{"straight", "right_loop"}));
  EXPECT_EQ(table.methods, (std::vector<std::string>{"oracle", "random"}));
  const std::string csv = deploy::render_csv(report);
  const std::string md = deploy::render_markdown(report, "town01", "town02");
  for (const auto& [method, cells] : by_hand) {
    std::map<std::string, double> town_sum;
    for (const auto& [key, counts] : cells) {
      const auto& [town, route] = key;
      const deploy::CellStats& cell = table.cells.at(method).at(town).at(route);
      const double sr = 100.0 * counts.second / counts.first;
      EXPECT_EQ(cell.episodes, 2);
      EXPECT_EQ(cell.successes, counts.second);
      EXPECT_DOUBLE_EQ(cell.sr, sr);
      town_sum[town] += sr;
      char line[160];
      std::snprintf(line, sizeof(line), "zero_shot,exploration,%s,%s,%s,1,2,%d,%.3f,%.3f,",
                    method.c_str(), town.c_str(), route.c_str(), counts.second, sr, 100.0 - sr);
      EXPECT_NE(csv.find(line), std::string::npos) << line << "\n" << csv;
    }
    // Average over the two routes per town and the town01 - town02 gap.
    char average[128];
    std::snprintf(average, sizeof(average), "| %s | %.1f | %.1f | %.1f |", method.c_str(),
                  town_sum["town01"] / 2.0, town_sum["town02"] / 2.0,
                  town_sum["town01"] / 2.0 - town_sum["town02"] / 2.0);
    EXPECT_NE(md.find(average), std::string::npos) << average << "\n" << md;
  }
  // Random episodes fail, and their reasons are counted per route.
  int random_failures = 0;
  for (const auto& [town, routes] : table.failures.at("random")) {
    for (const auto& [route, reasons] : routes) {
      for (const auto& [reason, n] : reasons) random_failures += n;
    }
  }
  EXPECT_EQ(random_failures, 8);
}

TEST(Evaluator, GridRowsMatchTheirEpisodesAndTheReportCellsMatchTheRows) {
  testing::TempDir dir;
  const std::vector<std::string> grid_keys = {
      "eval.towns=town01,town02", "eval.routes=straight,right_loop", "eval.densities=[10]",
      "eval.episodes_per_cell=2", "run.seed=4"};
  auto with = [&](std::vector<std::string> keys) {
    keys.insert(keys.end(), grid_keys.begin(), grid_keys.end());
    return keys;
  };
  const auto oracle_config = resolve(dir.path() / "oracle-s4", with({"eval.policy=oracle"}));
  const auto random_config = resolve(dir.path() / "random-s4", with({"eval.policy=random"}));
  std::vector<EpisodeRecord> rows = evaluate(oracle_config);
  const std::vector<EpisodeRecord> random_rows = evaluate(random_config);
  ASSERT_EQ(rows.size(), 8u);
  ASSERT_EQ(random_rows.size(), 8u);
  rows.insert(rows.end(), random_rows.begin(), random_rows.end());

  const ProtocolGrid grid{.towns = {"town01", "town02"},
                          .routes = {"straight", "right_loop"},
                          .densities = {10},
                          .episodes_per_cell = 2};
  const auto specs = grid.all_episodes();
  env::EnvConfig env_config = actor::env_config(oracle_config);
  env_config.events.time_limit_steps = 1 << 30;
  env::Env env(env_config);
  auto oracle = make_oracle_policy({});
  auto random = make_random_policy(4);  // run.seed
  ByHand by_hand;
  for (std::size_t i = 0; i < rows.size(); ++i) {
    const EpisodeRecord& row = rows[i];
    const EpisodeSpec& spec = specs[i % specs.size()];
    const bool is_oracle = i < specs.size();
    SCOPED_TRACE(row.method + " " + spec.town + "/" + spec.route + " episode " +
                 std::to_string(spec.episode));
    EXPECT_EQ(row.run_id, is_oracle ? "oracle-s4" : "random-s4");
    EXPECT_EQ(row.method, is_oracle ? "oracle" : "random");
    EXPECT_EQ(row.eval_kind, "zero_shot");
    EXPECT_EQ(row.task, "exploration");
    EXPECT_EQ(row.train_seed, 4);
    EXPECT_EQ(row.town, spec.town);
    EXPECT_EQ(row.route, spec.route);
    EXPECT_EQ(row.density, 10);
    EXPECT_EQ(row.episode, spec.episode);
    EXPECT_EQ(row.traffic_seed, kTrafficSeeds[spec.episode % 3]);
    EXPECT_EQ(row.spawn_seed, kSpawnSeeds[spec.episode % 5]);
    // The two episodes of a cell meet different traffic.
    if (spec.episode == 1) {
      EXPECT_NE(row.traffic_seed, rows[i - 1].traffic_seed);
    }

    // The episode replayed independently ends the same way.
    const Replay r = replay(env, spec, is_oracle ? *oracle : *random);
    const std::uint32_t failures = r.events & env::kFailureEvents;
    const bool success = (r.events & env::kDestination) != 0 && failures == 0;
    EXPECT_EQ(row.success, success);
    EXPECT_EQ(row.failure_reason, success ? "" : env::event_names(failures));
    EXPECT_EQ(row.steps, r.steps);
    EXPECT_NEAR(row.route_completion, route_completion(r.progress_m, r.length_m, r.events), 1e-6);
    EXPECT_LE(row.steps, route_step_budget(r.length_m));
    if (row.success) {
      EXPECT_GT(row.route_completion, 0.95);
    }
    EXPECT_EQ(row.episode_return, 0.0);  // no reward in zero-shot evaluation

    auto& cell = by_hand[row.method][{row.town, row.route}];
    ++cell.first;
    cell.second += row.success ? 1 : 0;
  }
  // The bounds the grid exists to show: the oracle drives these routes, random actions do not.
  for (const auto& [key, counts] : by_hand["oracle"]) EXPECT_EQ(counts.second, 2) << key.first;
  for (const auto& [key, counts] : by_hand["random"]) EXPECT_EQ(counts.second, 0) << key.first;

  expect_report_matches(rows, by_hand);
}

TEST(Evaluator, SnapshotFileIsEvaluatedWithoutALearner) {
  testing::TempDir dir;
  agent::AgentConfig agent_config = agent::preset("tiny");
  agent::Agent agent(agent_config);
  const auto file = dir.path() / "snapshot-v7.params";
  write_snapshot_file(file, agent.snapshot(), agent_config);
  // No DDS: a learner's snapshot would time out after 1 s and return 2. No preset either: the
  // file's header sizes the model and the camera (tiny, 32 px, where the default is cpu).
  const auto config = service::ServiceConfig::resolve(
      {.run_dir = dir.path() / "disag-s1",
       .overrides = {"eval.snapshot_file=" + file.string(), "eval.towns=town02",
                     "eval.routes=straight", "eval.densities=[5]", "eval.episodes_per_cell=2",
                     "eval.snapshot_timeout_s=1", "eval.video_episodes=1"}});
  ASSERT_EQ(config.agent().preset, "cpu");
  Evaluator evaluator(config, 0, 1);
  const std::atomic<bool> stop{false};
  ASSERT_EQ(evaluator.run(stop), 0);
  const auto rows = read_episode_csv(evaluator.results_file());
  ASSERT_EQ(rows.size(), 2u);
  for (const auto& row : rows) {
    EXPECT_EQ(row.method, "disag");
    EXPECT_EQ(row.town, "town02");
    EXPECT_EQ(row.success, row.failure_reason.empty());
    EXPECT_GT(row.steps, 0);
  }
  // The first episode of the cell was recorded; the second was not.
  EXPECT_TRUE(std::filesystem::exists(dir.path() / "disag-s1/videos/eval-town02-straight-5-0.mp4"));
  EXPECT_FALSE(
      std::filesystem::exists(dir.path() / "disag-s1/videos/eval-town02-straight-5-1.mp4"));
}

// --snapshot DIR names a finished run: its learner's final-snapshot.params; a directory without
// one is refused before anything starts, saying which files to name.
TEST(Evaluator, ARunDirectoryAsTheSnapshotMeansItsFinalSnapshot) {
  testing::TempDir dir;
  const auto finished = dir.path() / "finished-run";
  std::filesystem::create_directories(finished);
  agent::AgentConfig agent_config = agent::preset("tiny");
  write_snapshot_file(
      finished / "final-snapshot.params", agent::Agent(agent_config).snapshot(), agent_config,
      agent::SnapshotProvenance{.run_id = "finished-run", .version = 9, .env_steps = 900});
  auto evaluate = [&](const std::filesystem::path& given) {
    return service::ServiceConfig::resolve(
        {.run_dir = dir.path() / "again",
         .overrides = {"eval.snapshot_file=" + given.string(), "eval.towns=town02",
                       "eval.routes=straight", "eval.densities=[5]", "eval.episodes_per_cell=1",
                       "eval.snapshot_timeout_s=1"}});
  };
  {
    const auto config = evaluate(finished);
    Evaluator evaluator(config, 0, 1);
    const std::atomic<bool> stop{false};
    ASSERT_EQ(evaluator.run(stop), 0);
    EXPECT_EQ(read_episode_csv(evaluator.results_file()).size(), 1u);
  }
  const auto empty = dir.path() / "empty-run";
  std::filesystem::create_directories(empty);
  const auto empty_config = evaluate(empty);
  const std::string message =
      testing::error_of<EvalError>([&] { Evaluator evaluator(empty_config, 0, 1); });
  EXPECT_NE(message.find("without a final-snapshot.params"), std::string::npos) << message;
  EXPECT_NE(message.find("eval/snapshot-v<N>.params"), std::string::npos) << message;
}

// Lines of a learning-curve file after its header (0 when it does not exist yet).
std::vector<std::string> curve_rows(const std::filesystem::path& path) {
  std::vector<std::string> rows;
  std::ifstream in(path);
  std::string line;
  for (bool header = true; std::getline(in, line); header = false) {
    if (!header) rows.push_back(line);
  }
  return rows;
}

// A stand-in learner on DDS: publishes snapshots of one (untrained) agent and heartbeats.
struct StandInLearner {
  StandInLearner(const service::ServiceConfig& config)
      : config(config),
        agent_config(config.agent()),
        agent(agent_config),
        participant(dds::ParticipantOptions{.domain_id = config.domain_id(),
                                            .profiles_file = config.dds_profile()}),
        snapshots(participant.make_writer<msg::PolicySnapshot>()),
        announces(participant.make_writer<msg::SnapshotAnnounce>()),
        heartbeats(participant.make_writer<msg::Heartbeat>()) {}

  void publish(std::uint64_t version) {
    msg::PolicySnapshot snapshot;
    snapshot.run_id(config.run_id());
    snapshot.version(version);
    snapshot.preset(agent_config.preset);
    snapshot.architecture(service::architecture_descriptor(agent_config));
    snapshot.heads(msg::HEAD_ENCODER | msg::HEAD_RSSM | msg::HEAD_EXPLORATION_ACTOR);
    snapshot.phase(msg::PHASE_PRETRAIN);
    snapshot.env_steps(1000 * version);
    snapshot.params(agent.snapshot());
    dds::seal(snapshot);
    snapshots->write(snapshot);
    published = snapshot;
  }
  void beat(bool done, std::uint64_t version) {
    msg::Heartbeat heartbeat;
    heartbeat.role(msg::ROLE_LEARNER);
    heartbeat.run_id(config.run_id());
    heartbeat.state(done ? "done" : "running");
    heartbeat.policy_version(version);
    dds::seal(heartbeat);
    heartbeats->write(heartbeat);
  }

  // Announces the newest published snapshot.
  void announce(bool learner_done) {
    msg::SnapshotAnnounce announce = dds::announce_for(published);
    announce.learner_done(learner_done);
    dds::seal(announce);
    announces->write(announce);
  }

  const service::ServiceConfig& config;
  agent::AgentConfig agent_config;
  agent::Agent agent;
  dds::Participant participant;
  std::unique_ptr<dds::Writer<msg::PolicySnapshot>> snapshots;
  std::unique_ptr<dds::Writer<msg::SnapshotAnnounce>> announces;
  std::unique_ptr<dds::Writer<msg::Heartbeat>> heartbeats;
  msg::PolicySnapshot published;
};

// A run evaluated over DDS on a fresh domain: one episode (town02, straight, density 5).
service::ServiceConfig one_episode_over_dds(const std::filesystem::path& run_dir,
                                            std::vector<std::string> overrides) {
  overrides.insert(overrides.begin(),  // the caller's overrides come after, and win
                   {"eval.towns=town02", "eval.routes=straight", "eval.densities=[5]",
                    "eval.episodes_per_cell=1", "eval.snapshot_timeout_s=60",
                    "dds.domain_id=" + std::to_string(testing::unique_domain_id())});
  return resolve(run_dir, std::move(overrides));
}

// Checks that the run's evaluator wrote one row, for snapshot `version`.
void expect_one_row_of(const std::filesystem::path& run_dir, long long version) {
  const auto rows = read_episode_csv(run_dir / "eval/evaluator-0.csv");
  ASSERT_EQ(rows.size(), 1u);
  EXPECT_EQ(rows[0].policy_version, version);
}

// Runs one evaluator on `config` in a thread while `drive` plays the learner; returns the
// evaluator's exit code (-1 when it was still waiting after `drive` and 120 s more).
int evaluate_beside(const service::ServiceConfig& config, const std::function<void()>& drive) {
  std::atomic<bool> stop{false};
  std::atomic<int> code{-1};
  std::thread evaluator_thread([&] {
    Evaluator evaluator(config, 0, 1);
    code = evaluator.run(stop);
  });
  drive();
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(120);
  while (code.load() < 0 && std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  stop = true;
  evaluator_thread.join();
  return code.load();
}

// The default mode over DDS: the evaluator waits for the learner's final snapshot (v2 is
// published, but only v3 is announced as done), evaluates it, writes rows tagged with its
// version and keeps it as a snapshot file that evaluates again without DDS.
TEST(Evaluator, LearnersFinalSnapshotIsEvaluatedAndKeptAsAFile) {
  testing::TempDir dir;
  const auto config = one_episode_over_dds(dir.path() / "dds-run", {});
  StandInLearner learner(config);
  std::atomic<bool> stop{false};
  std::atomic<int> code{-1};
  std::thread evaluator_thread([&] {
    Evaluator evaluator(config, 0, 1);
    code = evaluator.run(stop);
  });
  learner.publish(2);
  for (int i = 0; i < 10; ++i) {  // 0.5 s of "running": v2 must not be taken
    learner.beat(false, 2);
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  learner.publish(3);
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(120);
  while (code.load() < 0 && std::chrono::steady_clock::now() < deadline) {
    learner.beat(true, 3);
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  stop = true;
  evaluator_thread.join();
  ASSERT_EQ(code.load(), 0);
  expect_one_row_of(dir.path() / "dds-run", 3);
  EXPECT_EQ(read_episode_csv(dir.path() / "dds-run/eval/evaluator-0.csv").at(0).method, "disag");
  const auto kept = dir.path() / "dds-run/eval/snapshot-v3.params";
  const SnapshotFile kept_file = read_snapshot_file(kept);
  EXPECT_EQ(kept_file.blob, learner.agent.snapshot());
  EXPECT_EQ(kept_file.value("preset"), "tiny") << "the kept file names its architecture";
  EXPECT_FALSE(std::filesystem::exists(dir.path() / "dds-run/eval/snapshot-v2.params"));
}

// The learner's reliable final announce alone ends the wait: its best-effort "done" heartbeat
// can be lost as the learner exits, which once left an evaluator waiting for an hour.
TEST(Evaluator, TheLearnersFinalAnnounceEndsTheWaitWithoutADoneHeartbeat) {
  testing::TempDir dir;
  const auto config =
      one_episode_over_dds(dir.path() / "announce-run", {"eval.learner_silence_s=0"});
  StandInLearner learner(config);
  const int code = evaluate_beside(config, [&] {
    // Announces are volatile, as they are from a learner that has long been matched.
    ASSERT_TRUE(learner.announces->wait_for_matched(1, std::chrono::seconds(30)));
    ASSERT_TRUE(learner.snapshots->wait_for_matched(1, std::chrono::seconds(30)));
    learner.publish(2);
    learner.publish(3);
    for (int i = 0; i < 10; ++i) {  // announced, not final: v3 must not be taken yet
      learner.beat(false, 3);
      learner.announce(false);
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    learner.announce(true);
    learner.announces->wait_for_acknowledgments(std::chrono::seconds(5));
  });
  ASSERT_EQ(code, 0);
  expect_one_row_of(dir.path() / "announce-run", 3);
}

// A learner that falls silent without declaring its last snapshot (it died, and nothing
// restarted it) leaves the newest snapshot held to be evaluated after eval.learner_silence_s,
// rather than an evaluator waiting until eval.snapshot_timeout_s.
TEST(Evaluator, ASilentLearnersNewestSnapshotIsEvaluatedAfterTheSilenceLimit) {
  testing::TempDir dir;
  const auto config = one_episode_over_dds(dir.path() / "silent-run", {"eval.learner_silence_s=1"});
  StandInLearner learner(config);
  const int code = evaluate_beside(config, [&] {
    learner.publish(4);
    for (int i = 0; i < 20; ++i) {  // 1 s of "running", longer than the limit: not yet taken
      learner.beat(false, 4);
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    EXPECT_FALSE(std::filesystem::exists(dir.path() / "silent-run/eval/snapshot-v4.params"))
        << "a learner still beating is waited for";
  });
  ASSERT_EQ(code, 0);
  expect_one_row_of(dir.path() / "silent-run", 4);
}

// An evaluator that receives nothing over DDS (restarted after its learner ended, or deaf to
// it) takes the learner's final snapshot file from the run directory once the learner has been
// silent for eval.learner_silence_s, and only a file of its own run and architecture.
TEST(Evaluator, WithNoSnapshotOverDdsTheLearnersFinalSnapshotFileIsEvaluated) {
  testing::TempDir dir;
  const auto run_dir = dir.path() / "file-run";
  auto config = one_episode_over_dds(
      run_dir, {"eval.learner_silence_s=1", "eval.snapshot_timeout_s=4", "actor.rejoin_after_s=0"});
  agent::Agent agent(config.agent());
  std::filesystem::create_directories(run_dir);
  const auto file = run_dir / "final-snapshot.params";

  // Another run's file, and a file of this run with other sizes: refused, so nothing arrives.
  write_snapshot_file(
      file, agent.snapshot(), config.agent(),
      agent::SnapshotProvenance{.run_id = "other", .version = 7, .env_steps = 7000});
  EXPECT_EQ(evaluate_beside(config, [] {}), 2) << "another run's final snapshot is not this one's";
  agent::AgentConfig wider = config.agent();
  wider.behavior.units *= 2;
  write_snapshot_file(
      file, agent::Agent(wider).snapshot(), wider,
      agent::SnapshotProvenance{.run_id = config.run_id(), .version = 7, .env_steps = 7000});
  EXPECT_EQ(evaluate_beside(config, [] {}), 2) << "a final snapshot of other sizes is refused";
  EXPECT_FALSE(std::filesystem::exists(run_dir / "eval/evaluator-0.csv"));

  write_snapshot_file(
      file, agent.snapshot(), config.agent(),
      agent::SnapshotProvenance{.run_id = config.run_id(), .version = 7, .env_steps = 7000});
  ASSERT_EQ(evaluate_beside(config, [] {}), 0);
  expect_one_row_of(run_dir, 7);
  EXPECT_EQ(read_snapshot_file(run_dir / "eval/snapshot-v7.params").blob, agent.snapshot());
}

// Continuous mode against a stand-in learner: snapshots v1..v5 with every_k = 2 give curve
// rows for v1 (the first), v3 (two on) and v5 (the final one, announced as done); v2 and v4
// are skipped. Each row carries its snapshot's version and env steps.
TEST(Evaluator, ContinuousModeEvaluatesEveryKthSnapshotIntoALearningCurve) {
  testing::TempDir dir;
  const auto config = resolve(
      dir.path() / "curve-run",
      {"eval.continuous=true", "eval.every_k=2", "eval.towns=town02", "eval.routes=straight",
       "eval.densities=[5]", "eval.episodes_per_cell=1", "eval.snapshot_timeout_s=60",
       "dds.domain_id=" + std::to_string(testing::unique_domain_id())});
  StandInLearner learner(config);
  auto publish = [&](std::uint64_t version) { learner.publish(version); };
  auto beat = [&](bool done, std::uint64_t version) { learner.beat(done, version); };

  std::atomic<bool> stop{false};
  std::atomic<int> code{-1};
  const auto curve = dir.path() / "curve-run" / "eval" / "curve-0.csv";
  std::thread evaluator_thread([&] {
    Evaluator evaluator(config, 0, 1);
    code = evaluator.run(stop);
  });
  // Publishes `version` and waits until the curve holds `rows` rows.
  auto step = [&](std::uint64_t version, std::size_t rows, bool done) {
    publish(version);
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(120);
    while (curve_rows(curve).size() < rows && std::chrono::steady_clock::now() < deadline &&
           code.load() < 0) {
      beat(done, version);
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
  };
  step(1, 1, false);
  step(2, 1, false);
  std::this_thread::sleep_for(std::chrono::milliseconds(500));  // v2 must not be evaluated
  EXPECT_EQ(curve_rows(curve).size(), 1u);
  step(3, 2, false);
  step(4, 2, false);
  step(5, 3, true);
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
  while (code.load() < 0 && std::chrono::steady_clock::now() < deadline) {
    beat(true, 5);
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  stop = true;
  evaluator_thread.join();
  EXPECT_EQ(code.load(), 0);

  const auto rows = curve_rows(curve);
  ASSERT_EQ(rows.size(), 3u);
  const char* expected[] = {"1000,1,disag,zero_shot,exploration,town02,straight,5,",
                            "3000,3,disag,zero_shot,exploration,town02,straight,5,",
                            "5000,5,disag,zero_shot,exploration,town02,straight,5,"};
  for (int i = 0; i < 3; ++i) EXPECT_EQ(rows[i].rfind(expected[i], 0), 0u) << rows[i];
  // The report reads results, not curves: this run has none.
  EXPECT_THROW(deploy::load_results({dir.path() / "curve-run"}), CsvError);
}

// Continuous mode whose learner ends without its final snapshot reaching the evaluator (its
// "done" heartbeat names v5, v5 never comes over DDS): the curve's last row is v5 from the
// learner's final snapshot file, and the evaluator ends without waiting for more.
TEST(Evaluator, ContinuousModeEndsTheCurveWithTheLearnersFinalSnapshotFile) {
  testing::TempDir dir;
  const auto run_dir = dir.path() / "curve-file-run";
  const auto config =
      resolve(run_dir, {"eval.continuous=true", "eval.every_k=2", "eval.towns=town02",
                        "eval.routes=straight", "eval.densities=[5]", "eval.episodes_per_cell=1",
                        "eval.snapshot_timeout_s=60", "actor.request_after_s=600",
                        "dds.domain_id=" + std::to_string(testing::unique_domain_id())});
  StandInLearner learner(config);
  const auto curve = run_dir / "eval" / "curve-0.csv";
  const int code = evaluate_beside(config, [&] {
    learner.publish(1);
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(120);
    while (curve_rows(curve).empty() && std::chrono::steady_clock::now() < deadline) {
      learner.beat(false, 1);
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    write_snapshot_file(
        run_dir / "final-snapshot.params", learner.agent.snapshot(), config.agent(),
        agent::SnapshotProvenance{.run_id = config.run_id(), .version = 5, .env_steps = 5000});
    for (int i = 0; i < 10; ++i) {
      learner.beat(true, 5);
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
  });
  ASSERT_EQ(code, 0);
  const auto rows = curve_rows(curve);
  ASSERT_EQ(rows.size(), 2u);
  EXPECT_EQ(rows[0].rfind("1000,1,", 0), 0u) << rows[0];
  EXPECT_EQ(rows[1].rfind("5000,5,", 0), 0u) << rows[1];
}

// The message of the EvalError constructing an evaluator throws ("" when none).
std::string setup_error(const service::ServiceConfig& config) {
  try {
    Evaluator evaluator(config, 0, 1);
  } catch (const EvalError& error) {
    return error.what();
  }
  return "";
}

TEST(Evaluator, BadInputsAreClearErrorsBeforeAnythingStarts) {
  testing::TempDir dir;
  std::string message =
      setup_error(resolve(dir.path() / "r", {"eval.policy=oracle", "eval.towns=town01,town9"}));
  EXPECT_NE(message.find("unknown evaluation town 'town9'"), std::string::npos) << message;
  EXPECT_NE(message.find("town01, town02"), std::string::npos) << message;

  message = setup_error(resolve(dir.path() / "r", {"eval.policy=oracle", "eval.routes=loop"}));
  EXPECT_NE(message.find("unknown evaluation route 'loop'"), std::string::npos) << message;

  // A pretraining snapshot has no task actor: few-shot evaluation of it is refused.
  agent::Agent agent(agent::preset("tiny"));
  const auto file = dir.path() / "pretrain.params";
  write_snapshot_file(file, agent.snapshot(), agent::preset("tiny"));
  message = setup_error(
      resolve(dir.path() / "r", {"eval.snapshot_file=" + file.string(), "eval.kind=few_shot"}));
  EXPECT_NE(message.find(file.string()), std::string::npos) << message;
  EXPECT_NE(message.find("not task_actor"), std::string::npos) << message;

  // Sizes chosen against the file's: both values named, and what to do.
  message = setup_error(service::ServiceConfig::resolve(
      {.run_dir = dir.path() / "r",
       .overrides = {"preset=cpu", "eval.snapshot_file=" + file.string()}}));
  EXPECT_NE(message.find("was trained with preset tiny"), std::string::npos) << message;
  EXPECT_NE(message.find("world_model.image=64 (preset 'cpu') where the file has 32"),
            std::string::npos)
      << message;
  EXPECT_NE(message.find("drop --set preset=cpu"), std::string::npos) << message;

  message = setup_error(resolve(
      dir.path() / "r", {"eval.snapshot_file=" + (dir.path() / "missing.params").string()}));
  EXPECT_NE(message.find("missing.params does not exist"), std::string::npos) << message;

  message = setup_error(resolve(dir.path() / "r", {"eval.policy=oracle", "eval.continuous=true"}));
  EXPECT_NE(message.find("--continuous"), std::string::npos) << message;
}

// eval.resume: an evaluation killed part-way (its last row cut) goes on where it stopped, runs
// no episode twice, and refuses a results file of another evaluation.
TEST(Evaluator, AStoppedEvaluationResumesWhereItStoppedAndRefusesAnotherEvaluationsRows) {
  testing::TempDir dir;
  const std::vector<std::string> keys = {"eval.policy=oracle", "eval.towns=town02",
                                         "eval.routes=straight", "eval.densities=[5]",
                                         "eval.episodes_per_cell=3"};
  auto with = [&](std::vector<std::string> more) {
    more.insert(more.begin(), keys.begin(), keys.end());
    return resolve(dir.path() / "oracle", more);
  };
  const std::vector<EpisodeRecord> whole = evaluate(with({}));
  ASSERT_EQ(whole.size(), 3u);
  const auto file = dir.path() / "oracle/eval/evaluator-0.csv";

  // As a kill leaves it: the header, the first row and part of the second.
  std::ifstream in(file);
  std::string header, first, second;
  std::getline(in, header);
  std::getline(in, first);
  std::getline(in, second);
  in.close();
  std::ofstream(file, std::ios::trunc) << header << '\n'
                                       << first << '\n'
                                       << second.substr(0, second.size() / 2);

  const std::vector<EpisodeRecord> resumed = evaluate(with({"eval.resume=true"}));
  ASSERT_EQ(resumed.size(), 3u);
  for (std::size_t i = 0; i < 3; ++i) {
    EXPECT_EQ(resumed[i].episode, static_cast<int>(i));
    EXPECT_EQ(resumed[i].success, whole[i].success) << i;
    EXPECT_EQ(resumed[i].steps, whole[i].steps) << i;
    EXPECT_EQ(resumed[i].failure_reason, whole[i].failure_reason) << i;
  }
  // Finished: resuming again runs nothing and adds no row.
  EXPECT_EQ(evaluate(with({"eval.resume=true"})).size(), 3u);
  // Without eval.resume the file is appended to, as before (a second evaluation of its own).
  EXPECT_EQ(evaluate(with({})).size(), 6u);

  // Rows of another evaluation: refused, naming the field, before any episode runs.
  std::ofstream(file, std::ios::trunc) << header << '\n' << first << '\n';
  std::string message;
  {
    // The evaluator keeps a reference to its config.
    const auto config = with({"eval.resume=true", "eval.protocol=indrive_code"});
    Evaluator evaluator(config, 0, 1);
    const std::atomic<bool> stop{false};
    message = testing::error_of<EvalError>([&] { evaluator.run(stop); });
  }
  EXPECT_NE(message.find("protocol 'strict', this one 'indrive_code'"), std::string::npos)
      << message;
  EXPECT_NE(message.find(file.string()), std::string::npos) << message;
  EXPECT_EQ(read_episode_csv(file).size(), 1u);
  // A row of this evaluation that another split of the grid runs (--id 1 --of 2 runs the
  // second episode of the cell, not the first).
  std::ofstream(dir.path() / "oracle/eval/evaluator-1.csv") << header << '\n' << first << '\n';
  {
    const auto config = with({"eval.resume=true"});
    Evaluator evaluator(config, 1, 2);
    const std::atomic<bool> stop{false};
    message = testing::error_of<EvalError>([&] { evaluator.run(stop); });
  }
  EXPECT_NE(message.find("not an episode of this evaluator's share"), std::string::npos) << message;
  // A learning curve is not resumed.
  message = setup_error(with({"eval.resume=true", "eval.continuous=true"}));
  EXPECT_NE(message.find("eval.resume"), std::string::npos) << message;
}

}  // namespace
}  // namespace indrive::actor
