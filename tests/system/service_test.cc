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
#include "process_harness.h"
#include "testing.h"

namespace indrive {
namespace {

using namespace std::chrono_literals;
namespace fs = std::filesystem;

using testing::Child;
using testing::slurp;

// The watch's participant can come out deaf to a learner that both actors hear (a CI run on
// 2026-12-07 under load: no snapshot, no heartbeat and none of the injected chunks in 60 s,
// the actors switching snapshots throughout). Like the services' own participants, it is
// replaced when it has not heard the learner, or its chunk writer has not found the learner's
// reader, for 5 s while the actors are heard. Call check() while waiting.
class LearnerHearing {
 public:
  explicit LearnerHearing(testing::ProcessWatch& watch) : watch_(watch) {}
  void check() {
    const double now = watch_.now_s();
    testing::SeenHeartbeat beat;
    const bool heard = watch_.heartbeat(msg::ROLE_LEARNER, 0, beat) && now - beat.time_s < 2.0;
    // Its own reader and the learner's.
    if ((heard && watch_.chunk_writer().matched() >= 2) || watch_.chunks().empty()) {
      deaf_since_ = -1.0;
    } else if (deaf_since_ < 0.0) {
      deaf_since_ = now;
    } else if (now - deaf_since_ > 5.0) {
      watch_.replace("the learner unheard or unmatched for 5 s while the actors are heard");
      deaf_since_ = -1.0;
    }
  }

 private:
  testing::ProcessWatch& watch_;
  double deaf_since_ = -1.0;
};

// A chunk of another run and a chunk of run "itest" with a bad checksum (actor 9, two steps).
std::vector<msg::TrajectoryChunk> foreign_and_corrupt_chunks() {
  std::vector<msg::TrajectoryChunk> chunks;
  const std::vector<std::uint8_t> frame(32 * 32, 1);
  for (const char* run : {"another-run", "itest"}) {
    actor::ChunkBuilder builder(
        {.run_id = run, .actor_id = 9, .height = 32, .width = 32, .chunk_length = 2});
    builder.add({.frame = frame, .is_first = true, .episode_step = 0});
    builder.add({.frame = frame, .episode_step = 1});
    chunks.push_back(builder.take());
  }
  chunks.back().checksum(chunks.back().checksum() ^ 1u);
  return chunks;
}

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
  testing::ProcessWatch watch(domain_, testing::source_path("deploy/dds/single_host.xml"));
  auto learner = start_learner();
  auto actor0 = start_actor(0);
  auto actor1 = start_actor(1);
  const auto state = [&] { return watch.describe() + logs(); };

  LearnerHearing hearing(watch);
  const auto running = [&] { return learner->running() && actor0->running() && actor1->running(); };

  // Both actors must act with a snapshot of version >= 2 (they start with the random policy,
  // version 0), and the watch must hear the learner's snapshots and heartbeats.
  testing::wait_until(100s, [&] {
    hearing.check();
    return !running() || (watch.min_newest_chunk_version({0, 1}) >= 2 &&
                          watch.newest_snapshot() >= 2 && watch.chunk_writer().matched() >= 2);
  });
  ASSERT_TRUE(running()) << state();
  ASSERT_GE(watch.min_newest_chunk_version({0, 1}), 2u) << state();
  ASSERT_GE(watch.newest_snapshot(), 2u) << state();
  for (const auto& snapshot : watch.snapshots()) EXPECT_GT(snapshot.bytes, 0u);
  std::map<std::uint32_t, std::vector<std::uint64_t>> versions;  // per actor, in order
  for (const auto& chunk : watch.chunks()) versions[chunk.actor_id].push_back(chunk.policy_version);
  for (std::uint32_t actor : {0u, 1u}) {
    EXPECT_TRUE(std::is_sorted(versions[actor].begin(), versions[actor].end()))
        << "actor " << actor << " never goes back to an older snapshot";
  }

  // Each actor started with the random policy and switched to a snapshot (the watch may match
  // after the first chunks, so this is read from the actors' logs).
  for (const auto& name : {"actor-0.log", "actor-1.log"}) {
    EXPECT_NE(slurp(dir_.path() / name).find("acting with snapshot v"), std::string::npos) << name;
  }

  // A chunk of another run and a chunk with a bad checksum: dropped, counted, no crash. Written
  // once the watch's writer has found the learner's reader (checked just above).
  for (const auto& chunk : foreign_and_corrupt_chunks()) {
    ASSERT_TRUE(watch.chunk_writer().write(chunk));
  }
  EXPECT_TRUE(watch.chunk_writer().wait_for_acknowledgments(10000ms)) << state();
  // Until a metrics line counts both (one comes every second), not for a fixed time.
  testing::wait_until(60s, [&] {
    const auto line = last_metrics();  // null until the first line is written
    return !learner->running() || (line.is_object() && line.value("dropped_wrong_run", 0) >= 1 &&
                                   line.value("dropped_bad_checksum", 0) >= 1);
  });
  EXPECT_TRUE(learner->running()) << state();

  // SIGTERM: the learner checkpoints and exits cleanly.
  learner->signal(SIGTERM);
  ASSERT_EQ(learner->wait(60s), 0) << state();
  const auto metrics = last_metrics();
  ASSERT_FALSE(metrics.empty()) << "metrics.jsonl must have lines";
  EXPECT_EQ(metrics.value("dropped_wrong_run", 0), 1) << metrics.dump() << state();
  EXPECT_EQ(metrics.value("dropped_bad_checksum", 0), 1) << metrics.dump();
  EXPECT_GT(metrics.value("updates", 0), 0);
  EXPECT_GT(metrics.value("env_steps", 0), 128);
  EXPECT_TRUE(fs::exists(run_dir_ / "config.yaml"));
  ASSERT_FALSE(fs::is_empty(run_dir_ / "checkpoints"));
  const std::uint64_t version_before = metrics.value("policy_version", 0);
  const std::uint64_t steps_before = metrics.value("env_steps", 0);

  // The actors keep their snapshot and wait; a restarted learner resumes from its checkpoint
  // and the version sequence and step counters continue.
  std::this_thread::sleep_for(1s);
  EXPECT_TRUE(actor0->running() && actor1->running()) << state();
  learner = start_learner();
  testing::wait_until(60s, [&] {
    hearing.check();
    return !running() || watch.min_newest_chunk_version({0, 1}) > version_before;
  });
  ASSERT_TRUE(running()) << state();
  EXPECT_GT(watch.min_newest_chunk_version({0, 1}), version_before) << state();
  // The resumed learner stored new steps (not only the chunks the test saw in flight).
  testing::wait_until(30s, [&] {
    hearing.check();
    testing::SeenHeartbeat beat;
    return watch.heartbeat(msg::ROLE_LEARNER, 0, beat) && beat.env_steps > steps_before;
  });
  learner->signal(SIGTERM);
  ASSERT_EQ(learner->wait(60s), 0) << state();
  const auto resumed = last_metrics();
  EXPECT_GT(resumed.value("env_steps", 0u), steps_before);
  EXPECT_EQ(resumed.value("learner_epoch", 0), 2);
  actor0->signal(SIGTERM);
  actor1->signal(SIGTERM);
  EXPECT_EQ(actor0->wait(30s), 0) << state();
  EXPECT_EQ(actor1->wait(30s), 0) << state();
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
