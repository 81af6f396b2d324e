// Faults of the service as real processes on the tiny preset: an actor killed under
// `indrive launch`, a learner killed between checkpoints, a late-joining evaluator (also one
// that can only get the snapshot through the announce and re-request path, and one started after
// its learner ended, which takes the learner's final snapshot file), and foreign or
// corrupt snapshots sent to running actors. Each test prints the figures it measured.
#include <gtest/gtest.h>
#include <signal.h>

#include <algorithm>
#include <cstdio>
#include <fstream>
#include <map>
#include <optional>
#include <regex>
#include <sstream>
#include <thread>

#include "indrive/agent/replay.h"
#include "indrive/agent/snapshot_file.h"
#include "indrive/basics/episode_csv.h"
#include "indrive/basics/run_dir.h"
#include "indrive/learner/learner.h"
#include "process_harness.h"
#include "testing.h"

namespace indrive {
namespace {

using namespace std::chrono_literals;
namespace fs = std::filesystem;
using testing::Child;
using testing::ProcessWatch;
using testing::SeenChunk;
using testing::SeenHeartbeat;
using testing::wait_until;

constexpr int kChunkLength = 16;  // tiny_service_config()

class FaultTest : public ::testing::Test {
 protected:
  void SetUp() override {
    domain_ = testing::unique_domain_id();
    run_dir_ = dir_.path() / "runs" / "ftest";
    config_ = dir_.path() / "ftest.yaml";
    std::ofstream(config_) << testing::tiny_service_config();
  }

  std::vector<std::string> args(const std::string& program,
                                const std::vector<std::string>& overrides = {}) const {
    return testing::service_args(program, config_, run_dir_, domain_, profile_, overrides);
  }
  std::unique_ptr<Child> start_learner(const std::vector<std::string>& overrides = {}) {
    return std::make_unique<Child>(args("indrive-learner", overrides), dir_.path() / "learner.log");
  }
  std::unique_ptr<Child> start_actor(int id, const std::vector<std::string>& overrides = {}) {
    auto argv = args("indrive-actor", overrides);
    argv.insert(argv.end(), {"--id", std::to_string(id)});
    return std::make_unique<Child>(argv, dir_.path() / ("actor-" + std::to_string(id) + ".log"));
  }

  // Every log of the test directory and the launcher's run logs, for failure messages: the
  // learner's and the launcher's first (CI cuts a long failure message in the middle), then the
  // actors', each without the environment's per-episode lines (counted) and cut to its last
  // 4,000 characters.
  std::string logs() const {
    std::vector<fs::path> files;
    for (const fs::path& folder : {dir_.path(), run_dir_ / "logs"}) {
      if (!fs::is_directory(folder)) continue;
      for (const auto& entry : fs::directory_iterator(folder)) {
        if (entry.path().extension() == ".log") files.push_back(entry.path());
      }
    }
    std::stable_sort(files.begin(), files.end(), [](const fs::path& a, const fs::path& b) {
      const bool actor_a = a.filename().string().starts_with("actor");
      const bool actor_b = b.filename().string().starts_with("actor");
      return actor_a != actor_b ? actor_b : a.filename() < b.filename();
    });
    std::string text;
    for (const auto& file : files) {
      std::istringstream lines(testing::slurp(file));
      std::string body;
      int episodes = 0;
      for (std::string line; std::getline(lines, line);) {
        if (line.find("[env] episode ") != std::string::npos) {
          ++episodes;
        } else {
          body += line + "\n";
        }
      }
      if (body.size() > 4000) body = "...\n" + body.substr(body.size() - 4000);
      text += "----- " + file.parent_path().filename().string() + "/" + file.filename().string() +
              " (" + std::to_string(episodes) + " episode lines left out)\n" + body;
    }
    return text;
  }

  // The same after what the watch saw.
  std::string logs(ProcessWatch& watch) const { return watch.describe() + "\n" + logs(); }

  std::vector<nlohmann::json> metrics() const {
    return testing::read_metrics(run_dir_ / "metrics.jsonl");
  }

  void replaces_its_participant_until_a_late_learner_comes();

  testing::TempDir dir_{"indrive-fault"};
  int domain_ = 0;
  fs::path run_dir_;
  fs::path config_;
  fs::path profile_ = testing::source_path("deploy/dds/single_host.xml");
};

// The watch's own view of both actors: after a learner is killed with SIGKILL the watch replaces
// its participant if it stops hearing them (ProcessWatch::replace_if_unheard).
const std::vector<std::pair<std::uint32_t, std::uint32_t>> kBothActors = {{msg::ROLE_ACTOR, 0},
                                                                          {msg::ROLE_ACTOR, 1}};

struct ActorRestart {
  std::uint32_t actor_id = 0;
  double after_s = 0.0;
};

// Whether `later` comes from a newer process of the actor than `earlier` (the one restart).
bool from_new_process(const SeenChunk& earlier, const SeenChunk& later,
                      const std::optional<ActorRestart>& restart) {
  return restart && later.actor_id == restart->actor_id && earlier.time_s <= restart->after_s &&
         later.time_s > restart->after_s;
}

// Sum of steps and number of chunks of `chunks` (in arrival order); checks that every chunk is
// complete: L steps, or fewer when it ends an episode or when the actor switched to a newer
// snapshot after it (every chunk is made by one policy version). The switch shows in the
// actor's next chunk; a short chunk whose successor was never sent (its process was killed or
// stopped right after the switch) or never seen by the test (a hole in the sequence numbers)
// cannot be checked this way and is left to the learner's step count below.
std::pair<std::int64_t, std::int64_t> complete_chunks(
    const std::vector<SeenChunk>& chunks, std::optional<ActorRestart> restart = std::nullopt) {
  std::int64_t steps = 0;
  for (std::size_t i = 0; i < chunks.size(); ++i) {
    const SeenChunk& chunk = chunks[i];
    steps += chunk.num_steps;
    if (chunk.num_steps == kChunkLength || chunk.ends_episode) continue;
    const auto next =
        std::find_if(chunks.begin() + static_cast<std::ptrdiff_t>(i) + 1, chunks.end(),
                     [&](const SeenChunk& later) { return later.actor_id == chunk.actor_id; });
    if (next == chunks.end() || from_new_process(chunk, *next, restart) ||
        next->chunk_seq != chunk.chunk_seq + 1) {
      continue;
    }
    EXPECT_GT(next->policy_version, chunk.policy_version)
        << "actor " << chunk.actor_id << " sent chunk " << chunk.chunk_seq << " with "
        << chunk.num_steps << " steps that neither ends an episode nor precedes a new snapshot";
  }
  return {steps, static_cast<std::int64_t>(chunks.size())};
}

// Chunks the test never saw, from the sequence numbers: each actor process numbers its chunks
// from 0 (a restarted actor starts again at 0), so the numbers below the first one seen of a
// process and the holes between seen ones were sent but not observed. `restart` marks where a
// new process of one actor begins (its first chunk seen after that time), because on a loaded
// host the watch can miss so many of the new process's first chunks that its numbers look like
// a continuation of the old one's.
std::int64_t missed_chunks(const std::vector<SeenChunk>& chunks,
                           std::optional<ActorRestart> restart = std::nullopt) {
  std::map<std::uint32_t, std::int64_t> next;  // per actor: the next sequence number expected
  std::int64_t missed = 0;
  bool restart_seen = false;
  for (const auto& chunk : chunks) {
    const auto seq = static_cast<std::int64_t>(chunk.chunk_seq);
    auto it = next.find(chunk.actor_id);
    const bool new_process = restart && !restart_seen && chunk.actor_id == restart->actor_id &&
                             chunk.time_s > restart->after_s;
    if (new_process) restart_seen = true;
    if (it == next.end() || seq < it->second || new_process) {
      missed += seq;  // a new process: its chunks 0 .. seq - 1
    } else {
      missed += seq - it->second;
    }
    next[chunk.actor_id] = seq + 1;
  }
  return missed;
}

TEST_F(FaultTest, ActorKilledUnderLaunchIsRestartedAndRejoinsWithTheNewestSnapshot) {
  ProcessWatch watch(domain_, profile_);
  Child launcher({std::string(INDRIVE_BIN_DIR) + "/indrive", "launch", "--config", config_.string(),
                  "--run-id", "ftest", "--runs-dir", (dir_.path() / "runs").string(), "--actors",
                  "2", "--evaluators", "0", "--domain", std::to_string(domain_), "--dds-profile",
                  profile_.string(), "--status-interval", "2"},
                 dir_.path() / "launch.log");
  // Chunks and heartbeats travel on separate topics: under load the first learner heartbeat
  // can reach the watch after actors' chunks already carry version 2 (seen once in CI beside
  // the cluster test), so both are waited for.
  SeenHeartbeat learner_at_kill;
  ASSERT_TRUE(wait_until(90s, [&] {
    return watch.min_newest_chunk_version({0, 1}) >= 2 &&
           watch.heartbeat(msg::ROLE_LEARNER, 0, learner_at_kill);
  })) << logs(watch);
  const auto victims = testing::child_pids(launcher.pid(), {"--id", "0"});
  ASSERT_EQ(victims.size(), 1u) << logs(watch);
  const std::uint64_t newest_at_kill = watch.newest_snapshot();
  const double killed_at = watch.now_s();
  ASSERT_EQ(::kill(victims[0], SIGKILL), 0);
  std::int64_t last_seq_before_kill = -1;
  for (const auto& chunk : watch.chunks()) {
    if (chunk.actor_id == 0 && chunk.time_s <= killed_at) {
      last_seq_before_kill =
          std::max(last_seq_before_kill, static_cast<std::int64_t>(chunk.chunk_seq));
    }
  }

  // The launcher starts a new actor 0 after its back-off.
  pid_t restarted = -1;
  ASSERT_TRUE(wait_until(30s, [&] {
    const auto pids = testing::child_pids(launcher.pid(), {"--id", "0"});
    if (pids.size() == 1 && pids[0] != victims[0]) restarted = pids[0];
    return restarted > 0;
  })) << logs(watch);
  const double restart_seen_at = watch.now_s();
  const double respawned_s = restart_seen_at - killed_at;

  // It rejoins: its chunks come again and soon carry a version at least as new as the newest
  // snapshot when its predecessor died (it never acted with it before). Only chunks that
  // arrive after the new process was seen count: chunks the killed process had in flight can
  // arrive just after the kill (one with the newest version did, once, and passed for a rejoin).
  const auto actor0_after_restart = [&] {
    std::vector<SeenChunk> found;
    for (const auto& chunk : watch.chunks()) {
      if (chunk.actor_id == 0 && chunk.time_s > restart_seen_at) found.push_back(chunk);
    }
    return found;
  };
  double first_chunk_s = -1.0, newest_chunk_s = -1.0;
  std::uint64_t first_version = 0;
  ASSERT_TRUE(wait_until(60s,
                         [&] {
                           for (const auto& chunk : actor0_after_restart()) {
                             if (first_chunk_s < 0.0) {
                               first_chunk_s = chunk.time_s - killed_at;
                               first_version = chunk.policy_version;
                             }
                             if (chunk.policy_version >= newest_at_kill) {
                               newest_chunk_s = chunk.time_s - killed_at;
                               return true;
                             }
                           }
                           return false;
                         }))
      << "newest snapshot at the kill: v" << newest_at_kill << "\n"
      << logs(watch);

  // The learner carried on (it trained on actor 1's data meanwhile) and actor 1 kept its
  // process and kept sending. Not without a pause: a process killed while it held the lock of
  // one of its shared-memory ports makes every peer that writes to that port wait for Fast DDS's
  // lock timeout (1 s; "Interprocess mutex timeout when locking") until the port is marked not
  // ok, and the learner's writes (allowance, heartbeat) pause with it, so actor 1, held by the
  // replay ratio, waits too. Once in CI that pause outlasted actor 0's return (4.1 s). The bound
  // here is the run resuming: no gap of 10 s in actor 1's chunks after the kill.
  SeenHeartbeat learner_now;
  ASSERT_TRUE(watch.heartbeat(msg::ROLE_LEARNER, 0, learner_now));
  EXPECT_GT(learner_now.updates, learner_at_kill.updates);
  EXPECT_EQ(testing::child_pids(launcher.pid(), {"--id", "1"}).size(), 1u);
  const double checked_at = watch.now_s();
  double previous_s = killed_at, longest_gap_s = 0.0;
  for (const auto& chunk : watch.chunks()) {
    if (chunk.actor_id != 1 || chunk.time_s <= killed_at || chunk.time_s > checked_at) continue;
    longest_gap_s = std::max(longest_gap_s, chunk.time_s - previous_s);
    previous_s = chunk.time_s;
  }
  longest_gap_s = std::max(longest_gap_s, checked_at - previous_s);
  EXPECT_LT(longest_gap_s, 10.0) << "actor 1 must keep sending while actor 0 is down and after";
  std::printf(
      "[figures] actor kill -9 under launch: respawned after %.2f s, first chunk after %.2f s "
      "(v%llu), chunk with the newest snapshot v%llu after %.2f s; actor 1's longest pause "
      "%.2f s\n",
      respawned_s, first_chunk_s, static_cast<unsigned long long>(first_version),
      static_cast<unsigned long long>(newest_at_kill), newest_chunk_s, longest_gap_s);

  // Stop the actors first (a clean exit is not restarted) so the learner stores all they sent,
  // then the launcher.
  for (const char* id : {"0", "1"}) {
    for (pid_t pid : testing::child_pids(launcher.pid(), {"--id", id})) ::kill(pid, SIGTERM);
  }
  ASSERT_TRUE(wait_until(30s, [&] {
    return testing::child_pids(launcher.pid(), {"--id", "0"}).empty() &&
           testing::child_pids(launcher.pid(), {"--id", "1"}).empty();
  })) << logs(watch);
  std::this_thread::sleep_for(1500ms);
  launcher.signal(SIGINT);
  ASSERT_EQ(launcher.wait(60s), 0) << logs(watch);

  // Nothing partial entered replay: the learner stored exactly the complete chunks that went
  // over the wire, no more steps (a cut chunk of the killed actor) and no fewer.
  const auto lines = metrics();
  ASSERT_FALSE(lines.empty());
  const auto& last = lines.back();
  const auto seen = watch.chunks();
  // Chunks before the new process was seen are the killed process's (a new process needs
  // seconds to start SUMO and send its first chunk).
  const ActorRestart restart{0, restart_seen_at};
  const auto [steps, chunks] = complete_chunks(seen, restart);
  // On a loaded host the test's reader can match an actor's writer after its first chunks went
  // out (a volatile topic does not replay them); those are counted from the sequence numbers,
  // at most L steps each. With none missed the comparison is exact.
  const std::int64_t missed = missed_chunks(seen, restart);
  // The restarted actor starts from the run's seed like its predecessor, so its first chunks
  // can repeat the killed process's byte for byte; the learner drops those as `duplicate`
  // (at most L steps each) instead of storing the same experience twice.
  const std::int64_t repeats = last.value("dropped_duplicate", 0);
  EXPECT_EQ(last.value("chunks", -1), chunks + missed - repeats) << last.dump();
  EXPECT_GE(last.value("env_steps", -1), steps - repeats * kChunkLength) << last.dump();
  EXPECT_LE(last.value("env_steps", -1), steps + missed * kChunkLength) << last.dump();
  if (missed == 0 && repeats == 0) {
    EXPECT_EQ(last.value("env_steps", -1), steps) << last.dump();
  }
  EXPECT_EQ(last.value("replay_size", -1), last.value("env_steps", -2))
      << "capacity exceeds the run's steps";
  std::printf(
      "[figures] learner stored %lld steps in %lld chunks; the test saw %lld chunks "
      "(%lld missed before its reader matched)\n",
      static_cast<long long>(last.value("env_steps", 0)),
      static_cast<long long>(last.value("chunks", 0)), static_cast<long long>(chunks),
      static_cast<long long>(missed));
  EXPECT_EQ(last.value("dropped_chunks", -1), repeats) << "no drop but exact repeats";
  EXPECT_NE(testing::slurp(run_dir_ / "logs" / "actor-0.log").find("acting with snapshot v"),
            std::string::npos);
}

TEST_F(FaultTest, LearnerKilledActorsWaitAndARestartedLearnerResumesFromItsCheckpoint) {
  ProcessWatch watch(domain_, profile_);
  const std::vector<std::string> learner_overrides = {"learner.checkpoint_minutes=0.1"};
  auto learner = start_learner(learner_overrides);
  auto actor0 = start_actor(0);
  auto actor1 = start_actor(1);
  ASSERT_TRUE(wait_until(90s, [&] {
    return watch.min_newest_chunk_version({0, 1}) >= 2;
  })) << logs(watch);

  // Kill the learner after a checkpoint and after snapshots newer than that checkpoint went
  // out, so the restarted learner must not hand out those version numbers again.
  CheckpointFiles files(run_dir_ / "checkpoints", 3);
  learner::LearnerCounters at_checkpoint;
  std::vector<std::uint8_t> agent_bytes, replay_bytes;
  ASSERT_TRUE(wait_until(30s, [&] {
    const auto newest = files.newest();
    if (!newest) return false;
    at_checkpoint = learner::unpack_checkpoint(read_file(*newest), agent_bytes, &replay_bytes);
    return at_checkpoint.updates > 0 && watch.newest_snapshot() > at_checkpoint.policy_version;
  })) << logs(watch);
  const double killed_at = watch.now_s();
  learner->signal(SIGKILL);
  ASSERT_EQ(learner->wait(10s), 128 + SIGKILL);
  const auto newest = files.newest();
  ASSERT_TRUE(newest.has_value());
  at_checkpoint = learner::unpack_checkpoint(read_file(*newest), agent_bytes, &replay_bytes);
  EXPECT_FALSE(replay_bytes.empty()) << "checkpoints carry the replay";
  std::this_thread::sleep_for(300ms);  // snapshots still in flight
  const std::uint64_t published_before = watch.newest_snapshot();

  // The actors keep their snapshot and wait at the allowance: no chunks, heartbeats that say
  // so, and next to no CPU (no busy loop). An actor may still use the allowance it held at the
  // kill, and the kill can leave a shared-memory port locked, so that every write to it waits
  // out Fast DDS's 1 s lock timeout: once in CI actor 0's last allowed chunk came 2.8 s after
  // the kill. The quiet window therefore starts when both actors say they are waiting (a
  // heartbeat sent at least 1 s after the kill, when no allowance can still arrive), plus 1 s
  // for a chunk written just before that heartbeat to reach the test's reader.
  ASSERT_TRUE(wait_until(30s,
                         [&] {
                           for (std::uint32_t id : {0u, 1u}) {
                             SeenHeartbeat beat;
                             if (!watch.heartbeat(msg::ROLE_ACTOR, id, beat) ||
                                 beat.state != "waiting" || beat.time_s < killed_at + 1.0) {
                               return false;
                             }
                           }
                           return true;
                         }))
      << "both actors must say they wait for an allowance after the learner's kill\n"
      << logs(watch);
  const double waiting_after_s = watch.now_s() - killed_at;
  std::this_thread::sleep_for(1s);
  const auto quiet_from = watch.now_s();
  const double cpu0 = testing::cpu_seconds(actor0->pid());
  const double cpu1 = testing::cpu_seconds(actor1->pid());
  std::this_thread::sleep_for(3s);
  const double window_s = watch.now_s() - quiet_from;
  const double busy0 = (testing::cpu_seconds(actor0->pid()) - cpu0) / window_s;
  const double busy1 = (testing::cpu_seconds(actor1->pid()) - cpu1) / window_s;
  ASSERT_TRUE(actor0->running() && actor1->running()) << logs(watch);
  for (const auto& chunk : watch.chunks()) {
    EXPECT_LT(chunk.time_s, quiet_from) << "actor " << chunk.actor_id << " sent chunk "
                                        << chunk.chunk_seq << " with no learner to allow it";
  }
  std::uint64_t held[2] = {0, 0};
  for (std::uint32_t id : {0u, 1u}) {
    SeenHeartbeat beat;
    ASSERT_TRUE(watch.heartbeat(msg::ROLE_ACTOR, id, beat));
    EXPECT_EQ(beat.state, "waiting") << "actor " << id;
    EXPECT_GT(beat.time_s, quiet_from) << "actor " << id << " keeps its heartbeat";
    EXPECT_GE(beat.policy_version, 2u) << "actor " << id << " keeps its snapshot";
    held[id] = beat.policy_version;
  }
  EXPECT_LT(busy0, 0.25) << "actor 0 waits without spinning";
  EXPECT_LT(busy1, 0.25) << "actor 1 waits without spinning";

  // A restarted learner resumes from the checkpoint with its replay and trains again.
  const double restarted_at = watch.now_s();
  learner = start_learner(learner_overrides);
  double rejoin_s = -1.0;
  ASSERT_TRUE(wait_until(60s, [&] {
    watch.replace_if_unheard(kBothActors, 10.0);
    if (watch.min_newest_chunk_version({0, 1}) <= published_before) return false;
    rejoin_s = watch.now_s() - restarted_at;
    return true;
  })) << logs(watch);
  for (const auto& snapshot : watch.snapshots()) {
    if (snapshot.time_s > restarted_at) {
      EXPECT_GT(snapshot.version, published_before)
          << "a restarted learner reused a version it had already published";
    }
  }
  const std::int64_t checkpoint_steps = at_checkpoint.env_steps;
  ASSERT_TRUE(wait_until(30s, [&] {
    SeenHeartbeat beat;
    // Only the restarted learner's heartbeats: the killed one's last may
    // still be the newest.
    return watch.heartbeat(msg::ROLE_LEARNER, 0, beat) && beat.time_s > restarted_at + 0.5 &&
           beat.updates > static_cast<std::uint64_t>(at_checkpoint.updates) + 5;
  })) << logs(watch);
  actor0->signal(SIGTERM);
  actor1->signal(SIGTERM);
  EXPECT_EQ(actor0->wait(30s), 0) << logs(watch);
  EXPECT_EQ(actor1->wait(30s), 0) << logs(watch);
  learner->signal(SIGTERM);
  ASSERT_EQ(learner->wait(60s), 0) << logs(watch);

  // The log names the replay steps it restored: all the checkpoint held (capacity exceeds the
  // run), so nothing had to be refilled.
  const std::string learner_log = testing::slurp(dir_.path() / "learner.log");
  std::smatch match;
  ASSERT_TRUE(std::regex_search(learner_log, match, std::regex("with ([0-9]+) replay steps")))
      << learner_log;
  EXPECT_EQ(std::stoll(match[1]), checkpoint_steps);

  // Counters continue from the checkpoint; the epoch counts the starts.
  const auto lines = metrics();
  std::vector<nlohmann::json> resumed;
  for (const auto& line : lines) {
    if (line.value("learner_epoch", 0) == 2) resumed.push_back(line);
  }
  ASSERT_FALSE(resumed.empty()) << logs(watch);
  EXPECT_GE(resumed.front().value("env_steps", 0), checkpoint_steps);
  EXPECT_GE(resumed.front().value("updates", 0), at_checkpoint.updates);
  EXPECT_GT(resumed.back().value("env_steps", 0), checkpoint_steps);
  EXPECT_GT(resumed.back().value("updates", 0), at_checkpoint.updates + 5);
  EXPECT_GT(resumed.back().value("policy_version", 0u), published_before);
  // Nothing was lost: replay holds every step the learner counts, those from before the kill
  // (restored) and those after it, and the resumed learner never trained ahead of the ratio.
  for (const auto& line : resumed) {
    EXPECT_EQ(line.value("replay_size", -1), line.value("env_steps", -2)) << line.dump();
    EXPECT_LE(line.value("updates", 0.0) * 128.0, 4.0 * line.value("env_steps", 0.0))
        << line.dump();
  }
  const double ratio = resumed.back().value("replay_ratio", 0.0);
  std::printf(
      "[figures] learner kill -9: checkpoint at %lld steps / %lld updates / v%llu with %zu "
      "replay bytes, v%llu published before the kill; both actors waiting %.2f s after it, "
      "holding v%llu and v%llu, using %.3f and %.3f cores; after the restart both act with "
      "a newer snapshot in %.2f s; final ratio %.2f\n",
      static_cast<long long>(at_checkpoint.env_steps),
      static_cast<long long>(at_checkpoint.updates),
      static_cast<unsigned long long>(at_checkpoint.policy_version), replay_bytes.size(),
      static_cast<unsigned long long>(published_before), waiting_after_s,
      static_cast<unsigned long long>(held[0]), static_cast<unsigned long long>(held[1]), busy0,
      busy1, rejoin_s, ratio);
}

TEST_F(FaultTest, LearnerKilledUnderLaunchIsRestartedAndResumes) {
  ProcessWatch watch(domain_, profile_);
  Child launcher({std::string(INDRIVE_BIN_DIR) + "/indrive",
                  "launch",
                  "--config",
                  config_.string(),
                  "--run-id",
                  "ftest",
                  "--runs-dir",
                  (dir_.path() / "runs").string(),
                  "--actors",
                  "2",
                  "--evaluators",
                  "0",
                  "--domain",
                  std::to_string(domain_),
                  "--dds-profile",
                  profile_.string(),
                  "--set",
                  "learner.checkpoint_minutes=0.1",
                  "--status-interval",
                  "2"},
                 dir_.path() / "launch.log");
  const std::string learner_program = std::string(INDRIVE_BIN_DIR) + "/indrive-learner";
  CheckpointFiles files(run_dir_ / "checkpoints", 3);
  ASSERT_TRUE(wait_until(90s, [&] {
    return watch.min_newest_chunk_version({0, 1}) >= 2 && files.newest().has_value();
  })) << logs(watch);
  const auto victims = testing::child_pids(launcher.pid(), {learner_program});
  ASSERT_EQ(victims.size(), 1u) << logs(watch);
  ASSERT_EQ(::kill(victims[0], SIGKILL), 0);
  const double killed_at = watch.now_s();
  std::this_thread::sleep_for(200ms);
  const std::uint64_t published_before = watch.newest_snapshot();

  // The launcher starts it again; it resumes from the checkpoint and the actors, which waited,
  // act with its newer snapshots.
  pid_t restarted = -1;
  ASSERT_TRUE(wait_until(30s, [&] {
    const auto pids = testing::child_pids(launcher.pid(), {learner_program});
    if (pids.size() == 1 && pids[0] != victims[0]) restarted = pids[0];
    return restarted > 0;
  })) << logs(watch);
  const double respawned_s = watch.now_s() - killed_at;
  ASSERT_TRUE(wait_until(60s, [&] {
    watch.replace_if_unheard(kBothActors, 10.0);
    return watch.min_newest_chunk_version({0, 1}) > published_before;
  })) << logs(watch);
  const double rejoined_s = watch.now_s() - killed_at;
  EXPECT_EQ(testing::child_pids(launcher.pid(), {"--id", "0"}).size(), 1u);
  EXPECT_EQ(testing::child_pids(launcher.pid(), {"--id", "1"}).size(), 1u);
  // Training goes on after the resume: a later metrics line shows more updates than the first
  // line of the resumed learner (lines come every log interval, so wait for one).
  const auto trained_after_resume = [&] {
    const auto lines = metrics();
    const auto first = std::find_if(lines.begin(), lines.end(), [](const nlohmann::json& line) {
      return line.value("learner_epoch", 0) == 2;
    });
    return first != lines.end() && lines.back().value("updates", 0) > first->value("updates", 0);
  };
  EXPECT_TRUE(wait_until(60s, trained_after_resume)) << logs(watch);
  launcher.signal(SIGINT);
  ASSERT_EQ(launcher.wait(60s), 0) << logs(watch);

  const auto lines = metrics();
  const auto resumed = std::find_if(lines.begin(), lines.end(), [](const nlohmann::json& line) {
    return line.value("learner_epoch", 0) == 2;
  });
  ASSERT_NE(resumed, lines.end()) << logs(watch);
  EXPECT_GT(resumed->value("env_steps", 0), 0) << "resumed from the checkpoint, not from zero";
  EXPECT_GT(lines.back().value("updates", 0), resumed->value("updates", 0));
  EXPECT_NE(testing::slurp(run_dir_ / "logs" / "learner.log").find("resumed from"),
            std::string::npos);
  std::printf(
      "[figures] learner kill -9 under launch: respawned after %.2f s, both actors act with a "
      "snapshot newer than v%llu %.2f s after the kill\n",
      respawned_s, static_cast<unsigned long long>(published_before), rejoined_s);
}

// The single-host profiles with the policy reader made VOLATILE: a process using it never gets
// the transient-local history, only snapshots written after it joined.
fs::path volatile_policy_profile(const fs::path& folder) {
  std::string xml = testing::slurp(testing::source_path("deploy/dds/single_host.xml"));
  const auto reader = xml.find("<data_reader profile_name=\"policy_reader\">");
  const auto durability = xml.find("TRANSIENT_LOCAL", reader);
  if (reader == std::string::npos || durability == std::string::npos) return {};
  xml.replace(durability, std::string("TRANSIENT_LOCAL").size(), "VOLATILE");
  const fs::path path = folder / "volatile_policy.xml";
  std::ofstream(path) << xml;
  return path;
}

// How many times a process's log says it replaced its DDS participant (maybe_rejoin).
std::size_t participant_replacements(const fs::path& log) {
  const std::string text = testing::slurp(log);
  const std::string line = "recreating its DDS participant";
  std::size_t count = 0;
  for (auto at = text.find(line); at != std::string::npos; at = text.find(line, at + 1)) ++count;
  return count;
}

// Waits for an evaluator's "evaluates snapshot vN" line; returns N, or 0 on timeout.
std::uint64_t evaluated_version(const fs::path& log, std::chrono::seconds timeout) {
  std::uint64_t version = 0;
  wait_until(timeout, [&] {
    const std::string text = testing::slurp(log);
    std::smatch match;
    if (!std::regex_search(text, match, std::regex("evaluates snapshot v([0-9]+)"))) return false;
    version = std::stoull(match[1]);
    return true;
  });
  return version;
}

// An evaluator (re)started after its learner ended, as `indrive launch` restarts a killed one:
// no learner is left to send the final snapshot, so it takes the learner's final-snapshot.params
// from the run directory once eval.learner_silence_s has passed. (The chaos soak once failed on
// an evaluator that waited for a snapshot no one would send, 2026-12-06.)
TEST_F(FaultTest, AnEvaluatorStartedAfterItsLearnerEndedEvaluatesTheFinalSnapshotFile) {
  const std::vector<std::string> budget = {"run.budget_env_steps=512"};
  auto learner = start_learner(budget);
  auto actor = start_actor(0, budget);
  ASSERT_EQ(learner->wait(150s), 0) << logs();
  actor->signal(SIGTERM);
  EXPECT_EQ(actor->wait(30s), 0) << logs();
  const fs::path file = run_dir_ / "final-snapshot.params";
  ASSERT_TRUE(fs::exists(file)) << logs();
  const auto provenance = agent::read_snapshot_file(file).provenance();
  ASSERT_TRUE(provenance.has_value());
  EXPECT_EQ(provenance->version, metrics().back().value("policy_version", 0u));

  auto argv = testing::service_args(
      "indrive-actor", config_, run_dir_, domain_, profile_,
      {"eval.towns=town01", "eval.routes=straight", "eval.densities=[5]",
       "eval.episodes_per_cell=2", "eval.learner_silence_s=2", "eval.snapshot_timeout_s=60"});
  argv.insert(argv.end(), {"--evaluate", "--id", "0"});
  const auto started = std::chrono::steady_clock::now();
  Child evaluator(argv, dir_.path() / "evaluator-after.log");
  ASSERT_EQ(evaluator.wait(120s), 0) << logs();
  const double after_s = testing::seconds_since(started);
  const auto rows = read_episode_csv(run_dir_ / "eval" / "evaluator-0.csv");
  ASSERT_EQ(rows.size(), 2u) << logs();
  for (const auto& row : rows) {
    EXPECT_EQ(row.policy_version, static_cast<long long>(provenance->version));
  }
  EXPECT_NE(testing::slurp(dir_.path() / "evaluator-after.log").find("from " + file.string()),
            std::string::npos)
      << logs();
  std::printf(
      "[figures] evaluator started after its learner ended: v%llu from the final snapshot file, "
      "evaluated and done %.2f s after its process started\n",
      static_cast<unsigned long long>(provenance->version), after_s);
}

TEST_F(FaultTest, LateJoiningEvaluatorGetsTheNewestSnapshotAlsoThroughTheReRequestPath) {
  ProcessWatch watch(domain_, profile_);
  auto learner = start_learner();
  auto actor0 = start_actor(0);
  auto actor1 = start_actor(1);
  ASSERT_TRUE(wait_until(90s, [&] {
    return watch.min_newest_chunk_version({0, 1}) >= 2 && watch.newest_snapshot() >= 4;
  })) << logs(watch);

  // An evaluator joining while training goes on gets a snapshot at least as new as the newest
  // one published when it started (transient-local history).
  const std::vector<std::string> eval_overrides = {"eval.wait_for_done=false", "eval.towns=town01"};
  auto evaluator_args = [&](const fs::path& profile) {
    auto argv =
        testing::service_args("indrive-actor", config_, run_dir_, domain_, profile, eval_overrides);
    argv.insert(argv.end(), {"--evaluate", "--id", "0"});
    return argv;
  };
  const std::uint64_t newest_at_join = watch.newest_snapshot();
  const auto joined = std::chrono::steady_clock::now();
  {
    Child evaluator(evaluator_args(profile_), dir_.path() / "evaluator-history.log");
    const std::uint64_t version =
        evaluated_version(dir_.path() / "evaluator-history.log", std::chrono::seconds(60));
    const double after_s = testing::seconds_since(joined);
    EXPECT_GE(version, newest_at_join) << logs(watch);
    std::printf(
        "[figures] late evaluator (transient-local): v%llu (newest at its start v%llu) "
        "%.2f s after its process started\n",
        static_cast<unsigned long long>(version), static_cast<unsigned long long>(newest_at_join),
        after_s);
    evaluator.signal(SIGTERM);
    EXPECT_EQ(evaluator.wait(30s), 0) << logs(watch);
  }

  // With the actors stopped no new snapshot is published; an evaluator whose policy reader
  // gets no history must notice the announced version and re-request it.
  actor0->signal(SIGTERM);
  actor1->signal(SIGTERM);
  ASSERT_EQ(actor0->wait(30s), 0) << logs(watch);
  ASSERT_EQ(actor1->wait(30s), 0) << logs(watch);
  // The learner still does the updates it owes for the steps it got; after them it publishes
  // nothing new.
  std::uint64_t final_version = watch.newest_snapshot();
  std::uint64_t updates = 0;
  auto unchanged_since = std::chrono::steady_clock::now();
  ASSERT_TRUE(wait_until(90s, [&] {
    SeenHeartbeat beat;
    watch.heartbeat(msg::ROLE_LEARNER, 0, beat);
    if (watch.newest_snapshot() != final_version || beat.updates != updates) {
      final_version = watch.newest_snapshot();
      updates = beat.updates;
      unchanged_since = std::chrono::steady_clock::now();
    }
    // Replay ratio 4 with 8 x 16 steps per update: all updates due are done.
    return testing::seconds_since(unchanged_since) > 3.0 && beat.updates >= beat.env_steps / 32;
  })) << logs(watch);
  const fs::path volatile_profile = volatile_policy_profile(dir_.path());
  ASSERT_FALSE(volatile_profile.empty()) << "single_host.xml has no policy_reader profile";
  const double requested_from = watch.now_s();
  const auto started = std::chrono::steady_clock::now();
  {
    Child evaluator(evaluator_args(volatile_profile), dir_.path() / "evaluator-volatile.log");
    const std::uint64_t version =
        evaluated_version(dir_.path() / "evaluator-volatile.log", std::chrono::seconds(60));
    const double after_s = testing::seconds_since(started);
    EXPECT_EQ(version, final_version) << logs(watch);
    std::printf(
        "[figures] late evaluator (no history, announce + re-request): v%llu %.2f s "
        "after its process started\n",
        static_cast<unsigned long long>(version), after_s);
    evaluator.signal(SIGTERM);
    EXPECT_EQ(evaluator.wait(30s), 0) << logs(watch);
  }
  // The learner republished the same version on request rather than a new one.
  const auto snapshots = watch.snapshots();
  EXPECT_TRUE(std::any_of(snapshots.begin(), snapshots.end(), [&](const auto& snapshot) {
    return snapshot.time_s > requested_from && snapshot.version == final_version;
  }));
  EXPECT_EQ(watch.newest_snapshot(), final_version);
  learner->signal(SIGTERM);
  ASSERT_EQ(learner->wait(60s), 0) << logs(watch);
  const auto lines = metrics();
  ASSERT_FALSE(lines.empty());
  EXPECT_GE(lines.back().value("snapshot_requests", 0), 1) << lines.back().dump();
}

TEST_F(FaultTest, ActorsRejectForeignAndCorruptSnapshotsAndKeepRunning) {
  ProcessWatch watch(domain_, profile_);
  auto learner = start_learner();
  auto actor0 = start_actor(0);
  auto actor1 = start_actor(1);
  ASSERT_TRUE(wait_until(90s, [&] {
    return watch.min_newest_chunk_version({0, 1}) >= 2;
  })) << logs(watch);

  // A snapshot for another architecture and one with a bad checksum, both of this run and with
  // a version far above the learner's, so only the checks can keep the actors from taking it.
  const std::uint64_t newest = watch.newest_snapshot();  // the watch sees its own writes too
  auto writer = watch.participant().make_writer<msg::PolicySnapshot>();
  msg::PolicySnapshot foreign;
  foreign.run_id("ftest");
  foreign.version(1000000);
  foreign.preset("cpu");
  foreign.architecture("image=64 channels=3 cnn_depth=16 deter=256 units=256 stoch=32x32");
  foreign.heads(msg::HEAD_ENCODER | msg::HEAD_RSSM | msg::HEAD_EXPLORATION_ACTOR);
  foreign.params(std::vector<std::uint8_t>(4096, 7));
  dds::seal(foreign);
  // One at a time: the topic keeps only the newest sample (KEEP_LAST 1).
  ASSERT_TRUE(writer->write(foreign));
  ASSERT_TRUE(writer->wait_for_acknowledgments(10000ms));
  msg::PolicySnapshot corrupt = foreign;
  corrupt.version(2000000);
  dds::seal(corrupt);
  corrupt.checksum(corrupt.checksum() ^ 1u);
  ASSERT_TRUE(writer->write(corrupt));
  ASSERT_TRUE(writer->wait_for_acknowledgments(10000ms));

  // Each actor counts both (its heartbeat's dropped_messages) and goes on with the learner's
  // snapshots.
  ASSERT_TRUE(wait_until(30s, [&] {
    for (std::uint32_t id : {0u, 1u}) {
      SeenHeartbeat beat;
      if (!watch.heartbeat(msg::ROLE_ACTOR, id, beat) || beat.dropped_messages < 2) return false;
    }
    return true;
  })) << logs(watch);
  ASSERT_TRUE(wait_until(60s, [&] {
    const auto version = watch.min_newest_chunk_version({0, 1});
    return version > newest && version < 1000000;
  })) << logs(watch);
  EXPECT_TRUE(actor0->running() && actor1->running() && learner->running()) << logs(watch);
  for (const char* name : {"actor-0.log", "actor-1.log"}) {
    const std::string text = testing::slurp(dir_.path() / name);
    EXPECT_NE(text.find("does not match this actor's"), std::string::npos) << name;
    EXPECT_NE(text.find("bad_checksum"), std::string::npos) << name << "\n" << text;
  }
  writer.reset();
  actor0->signal(SIGTERM);
  actor1->signal(SIGTERM);
  EXPECT_EQ(actor0->wait(30s), 0) << logs(watch);
  EXPECT_EQ(actor1->wait(30s), 0) << logs(watch);
}

// An actor that hears nothing of its learner replaces its DDS participant every
// actor.rejoin_after_s, and the replaced participant still works: a learner that starts late is
// found and the actor trains with it, after which the replacements stop. With shared memory
// (single_host.xml) and over UDP (default.xml), where only a participant that never heard the
// learner is replaced (a stalled DDS Security handshake at the start looks like that).
void FaultTest::replaces_its_participant_until_a_late_learner_comes() {
  ProcessWatch watch(domain_, profile_);
  // 3 s, not less: the learner sends its heartbeat between updates, and one of its first
  // updates (oneDNN primitives made, the first snapshot written) once held it a little over 1 s,
  // long enough for an actor that had heard it to be replaced once more.
  auto actor0 = start_actor(0, {"actor.rejoin_after_s=3"});
  const auto rejoins = [&] { return participant_replacements(dir_.path() / "actor-0.log"); };
  ASSERT_TRUE(wait_until(60s, [&] { return rejoins() >= 2; })) << logs(watch);
  ASSERT_TRUE(actor0->running()) << logs(watch);
  EXPECT_TRUE(watch.chunks().empty()) << "no chunk without a learner's allowance";

  auto learner = start_learner();
  ASSERT_TRUE(wait_until(90s, [&] { return watch.min_newest_chunk_version({0}) >= 1; }))
      << logs(watch);
  // With the learner heard (its heartbeat comes every 100 ms), no more replacements.
  const std::size_t joined_after = rejoins();
  std::this_thread::sleep_for(3s);
  EXPECT_EQ(rejoins(), joined_after) << logs(watch);
  SeenHeartbeat beat;
  ASSERT_TRUE(watch.heartbeat(msg::ROLE_ACTOR, 0, beat));
  EXPECT_GE(beat.policy_version, 1u);
  std::printf(
      "[figures] actor alone over %s: %zu participant replacements before the learner came\n",
      profile_.filename().c_str(), joined_after);

  actor0->signal(SIGTERM);
  EXPECT_EQ(actor0->wait(30s), 0) << logs(watch);
  learner->signal(SIGTERM);
  EXPECT_EQ(learner->wait(60s), 0) << logs(watch);
}

TEST_F(FaultTest, AnActorThatHearsNoLearnerReplacesItsParticipantAndJoinsALateLearner) {
  replaces_its_participant_until_a_late_learner_comes();
}

// An evaluator that has heard nothing of its learner replaces its participant the same way
// (over UDP, where a stalled DDS Security handshake of a late evaluator was seen), waiting
// twice as long after each replacement up to actor.rejoin_max_s, and the replaced participant
// still gets the learner's snapshot once it comes.
TEST_F(FaultTest, AnEvaluatorThatNeverHeardItsLearnerReplacesItsParticipantAndGetsASnapshot) {
  profile_ = testing::source_path("deploy/dds/default.xml");
  const fs::path log = dir_.path() / "evaluator.log";
  auto argv = args("indrive-actor",
                   {"actor.rejoin_after_s=2", "actor.rejoin_max_s=4", "eval.wait_for_done=false",
                    "eval.towns=town01", "eval.snapshot_timeout_s=120"});
  argv.insert(argv.end(), {"--evaluate", "--id", "0"});
  Child evaluator(argv, log);
  const auto rejoins = [&] { return participant_replacements(log); };
  ASSERT_TRUE(wait_until(60s, [&] { return rejoins() >= 2; })) << logs();
  ASSERT_TRUE(evaluator.running()) << logs();
  const std::string waited = testing::slurp(log);
  EXPECT_NE(waited.find("for 2 s; recreating its DDS participant (rejoin 1; the next after 4 s"),
            std::string::npos)
      << waited;
  EXPECT_NE(waited.find("for 4 s; recreating its DDS participant (rejoin 2; the next after 4 s"),
            std::string::npos)
      << waited;

  auto learner = start_learner();
  auto actor0 = start_actor(0);
  EXPECT_GE(evaluated_version(log, std::chrono::seconds(90)), 1u) << logs();
  std::printf(
      "[figures] evaluator alone over default.xml: %zu participant replacements before "
      "the learner came\n",
      rejoins());
  evaluator.signal(SIGTERM);
  EXPECT_EQ(evaluator.wait(30s), 0) << logs();
  actor0->signal(SIGTERM);
  EXPECT_EQ(actor0->wait(30s), 0) << logs();
  learner->signal(SIGTERM);
  EXPECT_EQ(learner->wait(60s), 0) << logs();
}

TEST_F(FaultTest, OverUdpAnActorThatNeverHeardItsLearnerReplacesItsParticipantToo) {
  profile_ = testing::source_path("deploy/dds/default.xml");
  replaces_its_participant_until_a_late_learner_comes();
}

}  // namespace
}  // namespace indrive
