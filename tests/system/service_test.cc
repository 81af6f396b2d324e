// The service as real processes: one learner and two actors on the tiny preset over DDS on
// this host, watched by the test through its own DDS participant.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <fstream>
#include <map>
#include <mutex>
#include <nlohmann/json.hpp>
#include <set>
#include <thread>

#include "child_process.h"
#include "indrive/actor/chunk_builder.h"
#include "indrive/agent/snapshot_file.h"
#include "indrive/basics/episode_csv.h"
#include "indrive/dds/participant.h"
#include "testing.h"

namespace indrive {
namespace {

using namespace std::chrono_literals;
namespace fs = std::filesystem;

using testing::Child;
using testing::slurp;

// What the test sees on the wire.
struct Observed {
  std::mutex mutex;
  std::map<std::uint32_t, std::vector<std::uint64_t>> chunk_versions;  // per actor, in order
  std::uint64_t newest_snapshot = 0;
  std::uint64_t learner_env_steps = 0;  // from the learner's newest heartbeat
  std::uint64_t snapshot_bytes = 0;

  std::uint64_t min_newest_chunk_version() {
    std::lock_guard<std::mutex> lock(mutex);
    if (chunk_versions.size() < 2) return 0;
    std::uint64_t low = UINT64_MAX;
    for (auto& [actor, versions] : chunk_versions) low = std::min(low, versions.back());
    return low;
  }
};

class ServiceTest : public ::testing::Test {
 protected:
  void SetUp() override {
    domain_ = testing::unique_domain_id();
    run_dir_ = dir_.path() / "runs" / "itest";
    config_ = dir_.path() / "itest.yaml";
    std::ofstream(config_) << R"(preset: tiny
run:
  seed: 3
env:
  densities: [0]
  time_limit_steps: 150
actor:
  chunk_length: 16
  request_after_s: 1
agent:
  replay:
    prefill: 128
    capacity: 20000
learner:
  replay_ratio: 4
  snapshot_every: 2
  log_interval_s: 1
  announce_s: 0.5
)";
  }

  std::vector<std::string> args(const std::string& program) const {
    return {std::string(INDRIVE_BIN_DIR) + "/" + program,
            "--config",
            config_.string(),
            "--run-dir",
            run_dir_.string(),
            "--domain",
            std::to_string(domain_),
            "--dds-profile",
            testing::source_path("deploy/dds/single_host.xml").string()};
  }

  std::unique_ptr<Child> start_learner(const std::vector<std::string>& extra = {}) {
    auto argv = args("indrive-learner");
    argv.insert(argv.end(), extra.begin(), extra.end());
    return std::make_unique<Child>(argv, dir_.path() / "learner.log");
  }
  std::unique_ptr<Child> start_actor(int id, const std::vector<std::string>& extra = {}) {
    auto argv = args("indrive-actor");
    argv.insert(argv.end(), {"--id", std::to_string(id)});
    argv.insert(argv.end(), extra.begin(), extra.end());
    return std::make_unique<Child>(argv, dir_.path() / ("actor-" + std::to_string(id) + ".log"));
  }

  std::string logs() {
    std::string text;
    for (const auto& name : {"learner.log", "actor-0.log", "actor-1.log"}) {
      text += std::string("----- ") + name + "\n" + slurp(dir_.path() / name);
    }
    return text;
  }

  nlohmann::json last_metrics() {
    std::ifstream in(run_dir_ / "metrics.jsonl");
    std::string line, last;
    while (std::getline(in, line)) {
      if (!line.empty()) last = line;
    }
    return last.empty() ? nlohmann::json{} : nlohmann::json::parse(last);
  }

  testing::TempDir dir_{"indrive-service"};
  int domain_ = 0;
  fs::path run_dir_;
  fs::path config_;
};

TEST_F(ServiceTest, ActorsSwitchToRisingSnapshotsAndBadChunksAreDropped) {
  dds::Participant participant(
      {.domain_id = domain_,
       .profiles_file = testing::source_path("deploy/dds/single_host.xml").string()});
  Observed seen;
  auto chunk_reader =
      participant.make_reader<msg::TrajectoryChunk>([&](const msg::TrajectoryChunk& chunk) {
        if (chunk.actor_id() > 1) return;  // the test's own injected chunks
        std::lock_guard<std::mutex> lock(seen.mutex);
        seen.chunk_versions[chunk.actor_id()].push_back(chunk.policy_version());
      });
  auto snapshot_reader =
      participant.make_reader<msg::PolicySnapshot>([&](const msg::PolicySnapshot& snapshot) {
        std::lock_guard<std::mutex> lock(seen.mutex);
        seen.newest_snapshot = std::max(seen.newest_snapshot, snapshot.version());
        seen.snapshot_bytes = snapshot.params().size();
      });
  auto heartbeat_reader = participant.make_reader<msg::Heartbeat>([&](const msg::Heartbeat& beat) {
    if (beat.role() != msg::ROLE_LEARNER) return;
    std::lock_guard<std::mutex> lock(seen.mutex);
    seen.learner_env_steps = beat.env_steps();
  });
  auto chunk_writer = participant.make_writer<msg::TrajectoryChunk>();

  auto learner = start_learner();
  auto actor0 = start_actor(0);
  auto actor1 = start_actor(1);

  // Both actors must act with a snapshot of version >= 2 (they start with the random policy,
  // version 0) and the learner must have published at least version 3.
  const auto deadline = std::chrono::steady_clock::now() + 100s;
  while (std::chrono::steady_clock::now() < deadline && seen.min_newest_chunk_version() < 2) {
    ASSERT_TRUE(learner->running()) << logs();
    ASSERT_TRUE(actor0->running()) << logs();
    ASSERT_TRUE(actor1->running()) << logs();
    std::this_thread::sleep_for(200ms);
  }
  ASSERT_GE(seen.min_newest_chunk_version(), 2u) << logs();
  {
    std::lock_guard<std::mutex> lock(seen.mutex);
    EXPECT_GE(seen.newest_snapshot, 2u);
    EXPECT_GT(seen.snapshot_bytes, 0u);
    for (auto& [actor, versions] : seen.chunk_versions) {
      EXPECT_TRUE(std::is_sorted(versions.begin(), versions.end()))
          << "actor " << actor << " never goes back to an older snapshot";
    }
  }

  // Each actor started with the random policy and switched to a snapshot (the test's reader
  // may match after the first chunks, so this is read from the actors' logs).
  for (const auto& name : {"actor-0.log", "actor-1.log"}) {
    EXPECT_NE(slurp(dir_.path() / name).find("acting with snapshot v"), std::string::npos) << name;
  }

  // A chunk of another run and a chunk with a bad checksum: dropped, counted, no crash.
  actor::ChunkBuilder builder(
      {.run_id = "another-run", .actor_id = 9, .height = 32, .width = 32, .chunk_length = 2});
  std::vector<std::uint8_t> frame(32 * 32, 1);
  builder.add({.frame = frame, .is_first = true, .episode_step = 0});
  builder.add({.frame = frame, .episode_step = 1});
  ASSERT_TRUE(chunk_writer->write(builder.take()));
  actor::ChunkBuilder ours(
      {.run_id = "itest", .actor_id = 9, .height = 32, .width = 32, .chunk_length = 2});
  ours.add({.frame = frame, .is_first = true, .episode_step = 0});
  ours.add({.frame = frame, .episode_step = 1});
  auto corrupt = ours.take();
  corrupt.checksum(corrupt.checksum() ^ 1u);
  ASSERT_TRUE(chunk_writer->write(corrupt));
  chunk_writer->wait_for_acknowledgments(5000ms);
  // Until a metrics line counts both (one comes every second), not for a fixed time.
  const auto counted_deadline = std::chrono::steady_clock::now() + 60s;
  while (std::chrono::steady_clock::now() < counted_deadline && learner->running()) {
    const auto line = last_metrics();  // null until the first line is written
    if (line.is_object() && line.value("dropped_wrong_run", 0) >= 1 &&
        line.value("dropped_bad_checksum", 0) >= 1) {
      break;
    }
    std::this_thread::sleep_for(200ms);
  }
  EXPECT_TRUE(learner->running()) << logs();

  // SIGTERM: the learner checkpoints and exits cleanly.
  learner->signal(SIGTERM);
  ASSERT_EQ(learner->wait(60s), 0) << logs();
  const auto metrics = last_metrics();
  ASSERT_FALSE(metrics.empty()) << "metrics.jsonl must have lines";
  EXPECT_EQ(metrics.value("dropped_wrong_run", 0), 1) << metrics.dump();
  EXPECT_EQ(metrics.value("dropped_bad_checksum", 0), 1) << metrics.dump();
  EXPECT_GT(metrics.value("updates", 0), 0);
  EXPECT_GT(metrics.value("env_steps", 0), 128);
  EXPECT_TRUE(fs::exists(run_dir_ / "config.yaml"));
  ASSERT_FALSE(fs::is_empty(run_dir_ / "checkpoints"));
  const std::uint64_t version_before = metrics.value("policy_version", 0);
  const std::int64_t steps_before = metrics.value("env_steps", 0);

  // The actors keep their snapshot and wait; a restarted learner resumes from its checkpoint
  // and the version sequence and step counters continue.
  std::this_thread::sleep_for(1s);
  EXPECT_TRUE(actor0->running() && actor1->running()) << logs();
  learner = start_learner();
  const auto resume_deadline = std::chrono::steady_clock::now() + 60s;
  while (std::chrono::steady_clock::now() < resume_deadline &&
         seen.min_newest_chunk_version() <= version_before) {
    ASSERT_TRUE(learner->running()) << logs();
    std::this_thread::sleep_for(200ms);
  }
  EXPECT_GT(seen.min_newest_chunk_version(), version_before) << logs();
  // The resumed learner stored new steps (not only the chunks the test saw in flight).
  const auto stored_deadline = std::chrono::steady_clock::now() + 30s;
  while (std::chrono::steady_clock::now() < stored_deadline) {
    {
      std::lock_guard<std::mutex> lock(seen.mutex);
      if (seen.learner_env_steps > static_cast<std::uint64_t>(steps_before)) break;
    }
    std::this_thread::sleep_for(100ms);
  }
  learner->signal(SIGTERM);
  ASSERT_EQ(learner->wait(60s), 0) << logs();
  const auto resumed = last_metrics();
  EXPECT_GT(resumed.value("env_steps", 0), steps_before);
  EXPECT_EQ(resumed.value("learner_epoch", 0), 2);
  actor0->signal(SIGTERM);
  actor1->signal(SIGTERM);
  EXPECT_EQ(actor0->wait(30s), 0) << logs();
  EXPECT_EQ(actor1->wait(30s), 0) << logs();
}

// A learner that spends its budget declares its last snapshot in a reliable announce before it
// exits (its "done" heartbeat is best effort), so evaluators waiting for it are never left
// hanging. Only that announce says learner_done, and it names the newest snapshot.
TEST_F(ServiceTest, ALearnerAtItsBudgetAnnouncesItsLastSnapshotReliablyBeforeExiting) {
  dds::Participant participant(
      {.domain_id = domain_,
       .profiles_file = testing::source_path("deploy/dds/single_host.xml").string()});
  std::mutex mutex;
  std::uint64_t newest_snapshot = 0, final_announced = 0, done_announces = 0, announces = 0;
  bool announced_done_early = false;
  auto snapshot_reader =
      participant.make_reader<msg::PolicySnapshot>([&](const msg::PolicySnapshot& snapshot) {
        std::lock_guard<std::mutex> lock(mutex);
        newest_snapshot = std::max(newest_snapshot, snapshot.version());
      });
  auto announce_reader =
      participant.make_reader<msg::SnapshotAnnounce>([&](const msg::SnapshotAnnounce& announce) {
        std::lock_guard<std::mutex> lock(mutex);
        ++announces;
        if (!announce.learner_done()) {
          announced_done_early = announced_done_early || done_announces > 0;
          return;
        }
        ++done_announces;
        final_announced = announce.version();
      });
  const std::vector<std::string> budget = {"--set", "run.budget_env_steps=400"};
  // A final snapshot file left by an earlier end of this run is removed when the learner
  // starts, and the run's own end writes it again.
  fs::create_directories(run_dir_);
  std::ofstream(run_dir_ / "final-snapshot.params") << "an earlier end of this run";
  auto learner = start_learner(budget);
  // The budget comes from the actor's steps, so the actor starts only once this observer has
  // found the learner's writers: on a warm machine the whole run takes about 3.5 s, less than
  // discovery may take on a busy one, and an announce sent before the match is never heard.
  ASSERT_TRUE(announce_reader->wait_for_matched(1, 60s)) << logs();
  ASSERT_TRUE(snapshot_reader->wait_for_matched(1, 60s)) << logs();
  auto actor = start_actor(0, budget);
  ASSERT_EQ(learner->wait(150s), 0) << logs();
  actor->signal(SIGTERM);
  EXPECT_EQ(actor->wait(30s), 0) << logs();

  const auto metrics = last_metrics();
  std::lock_guard<std::mutex> lock(mutex);
  EXPECT_GT(announces, 1u) << "periodic announces came before the final one";
  EXPECT_GE(done_announces, 1u) << logs();
  EXPECT_FALSE(announced_done_early) << "no periodic announce after the final one";
  EXPECT_GT(final_announced, 0u);
  EXPECT_EQ(final_announced, newest_snapshot);
  EXPECT_EQ(final_announced, metrics.value("policy_version", 0u)) << metrics.dump();

  // The final snapshot is also a file in the run directory, for evaluators that missed it over
  // DDS and for evaluating the run later: the announced version, of this run, at its budget.
  const agent::SnapshotFile file = agent::read_snapshot_file(run_dir_ / "final-snapshot.params");
  const auto provenance = file.provenance();
  ASSERT_TRUE(provenance.has_value()) << agent::describe_snapshot_file(file);
  EXPECT_EQ(provenance->run_id, "itest");
  EXPECT_EQ(provenance->version, final_announced);
  EXPECT_GT(provenance->env_steps, 0u);
  EXPECT_LE(provenance->env_steps, metrics.value("env_steps", 0u)) << metrics.dump();
  EXPECT_EQ(file.value("preset"), "tiny");
  EXPECT_EQ(file.value("actor"), "expl_actor");
  EXPECT_NE(slurp(dir_.path() / "learner.log").find("removed the final snapshot file"),
            std::string::npos)
      << "the earlier end's file is removed at the start, not only overwritten at the end";

  // The same run's episodes (at most 151 steps each, so two or more within the budget) reach
  // the learner's metrics from the actor's EpisodeResults: their length, and their reach in
  // distinct lane segments, which counts at least the spawn's segment.
  ASSERT_TRUE(metrics.contains("episode_reach_last20")) << metrics.dump();
  EXPECT_GE(metrics["episode_reach_last20"].get<double>(), 1.0) << metrics.dump();
  EXPECT_GT(metrics["episode_length_last20"].get<double>(), 0.0) << metrics.dump();
  EXPECT_LE(metrics["episode_length_last20"].get<double>(), 151.0) << metrics.dump();
  // ... and each is a row of the learner's train-episodes.csv.
  const auto episodes = read_episode_csv(run_dir_ / "train-episodes.csv");
  ASSERT_GE(episodes.size(), 2u);
  for (std::size_t i = 0; i < episodes.size(); ++i) {
    EXPECT_EQ(episodes[i].episode, static_cast<int>(i));
    EXPECT_EQ(episodes[i].eval_kind, "training");
    EXPECT_EQ(episodes[i].task, "exploration");
    EXPECT_EQ(episodes[i].town, "town01");
    EXPECT_GT(episodes[i].steps, 0);
    EXPECT_LE(episodes[i].steps, 151);
  }

  // A learner started without `indrive launch` keeps the run's page (learner.dashboard_s, 30 s
  // by default) and ends it with how the run ended.
  const std::string page = slurp(run_dir_ / "index.html");
  EXPECT_NE(page.find("<span class=\"ended\">ended: budget reached at "), std::string::npos)
      << slurp(run_dir_ / "logs" / "dashboard.log");
  EXPECT_NE(slurp(dir_.path() / "learner.log").find("page: " + (run_dir_ / "index.html").string()),
            std::string::npos)
      << logs();
}

// --check-config checks each program's DDS Security files before anything starts: a good
// folder is named with the role it runs as; a certificate of another CA fails with the file's
// name, and nothing is left running.
TEST(CheckConfig, SecurityFilesAreCheckedForTheProgramsRole) {
  testing::TempDir dir("indrive-check-config");
  const fs::path security = dir.path() / "security";
  testing::make_security_folder(security);
  const fs::path config = dir.path() / "c.yaml";
  std::ofstream(config) << "preset: tiny\n";
  const std::string bin = INDRIVE_BIN_DIR;
  auto check = [&](const std::string& program, const std::string& extra, std::string& output) {
    return testing::run_command(bin + "/" + program + " --config '" + config.string() +
                                    "' --run-dir '" + (dir.path() / "runs/r").string() +
                                    "' --dds-security '" + security.string() + "' " + extra +
                                    " --check-config 2>&1",
                                output);
  };
  std::string output;
  EXPECT_EQ(check("indrive-learner", "", output), 0) << output;
  EXPECT_NE(output.find("DDS Security as learner from"), std::string::npos) << output;
  EXPECT_EQ(check("indrive-actor", "", output), 0) << output;
  EXPECT_NE(output.find("DDS Security as actor from"), std::string::npos) << output;
  EXPECT_EQ(check("indrive-actor", "--evaluate", output), 0) << output;
  EXPECT_NE(output.find("DDS Security as evaluator from"), std::string::npos) << output;

  // The actor's certificate replaced by the learner's: signed by the same CA, but its key and
  // the permissions' subject no longer match, which the check names.
  fs::copy_file(security / "learner.pem", security / "actor.pem",
                fs::copy_options::overwrite_existing);
  EXPECT_NE(check("indrive-actor", "", output), 0) << output;
  EXPECT_NE(output.find("actor.key' does not belong to"), std::string::npos) << output;
  EXPECT_EQ(output.find("config ok"), std::string::npos) << output;
  // The learner's own files are untouched and still pass.
  EXPECT_EQ(check("indrive-learner", "", output), 0) << output;
}

}  // namespace
}  // namespace indrive
