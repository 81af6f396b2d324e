// Helpers for tests that run the service as real processes: child processes with their output
// in a log file, a DDS participant that watches what travels on the wire, and readers of the
// run directory (metrics.jsonl) and of /proc (CPU time, children of a launcher).
//
//   ProcessWatch watch(domain, profile);                 // before the processes start
//   Child learner({bin + "/indrive-learner", ...}, dir / "learner.log");
//   wait_until(60s, [&] { return watch.newest_snapshot() >= 2; });
//   learner.signal(SIGKILL);
#pragma once

#include <sys/types.h>

#include <chrono>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "child_process.h"
#include "indrive/basics/stopwatch.h"
#include "indrive/dds/participant.h"

namespace indrive::testing {

using indrive::seconds_since;
using indrive::SteadyClock;

// Polls `condition` every 50 ms until it holds or `timeout` passes; returns its last value.
bool wait_until(std::chrono::milliseconds timeout, const std::function<bool()>& condition);

// Every line of a metrics.jsonl file, parsed, in order (lines that do not parse are skipped:
// a killed learner may leave a partial last line).
std::vector<nlohmann::json> read_metrics(const std::filesystem::path& path);

// Whether a metrics line keeps the replay ratio: no more updates than are due for its env
// steps (the learner never trains ahead), and env steps at most `lead_steps` ahead of what its
// updates cover (the actors' slack and the steps in flight).
bool keeps_ratio(const nlohmann::json& line, double ratio, double steps_per_update,
                 double lead_steps);

// User plus system CPU time of a process so far, in seconds (-1 when it is gone).
double cpu_seconds(pid_t pid);

// Pids of the live children of `parent` whose command line holds `words` as consecutive
// arguments, e.g. {"--id", "0"}.
std::vector<pid_t> child_pids(pid_t parent, const std::vector<std::string>& words);

// One TrajectoryChunk as the watch saw it.
struct SeenChunk {
  std::uint32_t actor_id = 0;
  std::uint64_t chunk_seq = 0;
  std::uint32_t num_steps = 0;
  std::uint64_t policy_version = 0;
  bool ends_episode = false;  // its last step is the last step of an episode
  double time_s = 0.0;        // seconds since the watch started
};

// One PolicySnapshot as the watch saw it.
struct SeenSnapshot {
  std::uint64_t version = 0;
  std::uint64_t updates = 0;
  std::size_t bytes = 0;
  std::uint32_t checksum = 0;
  double time_s = 0.0;
};

// The newest Heartbeat of one process.
struct SeenHeartbeat {
  std::string state;
  std::uint64_t env_steps = 0;
  std::uint64_t updates = 0;
  std::uint64_t policy_version = 0;
  std::uint64_t dropped_messages = 0;
  double time_s = 0.0;
};

// A DDS participant of the test that records the chunks of actors (ids below 100), every
// snapshot and the newest heartbeat of each process, and can write messages of its own.
class ProcessWatch {
 public:
  ProcessWatch(int domain_id, const std::filesystem::path& profiles_file);
  // With every participant option given (DDS Security, discovery server).
  explicit ProcessWatch(const dds::ParticipantOptions& options);
  ~ProcessWatch();

  std::vector<SeenChunk> chunks();
  std::vector<SeenSnapshot> snapshots();
  // Newest snapshot version seen (0: none).
  std::uint64_t newest_snapshot();
  // The newest heartbeat of (role, id), if one came.
  bool heartbeat(std::uint32_t role, std::uint32_t id, SeenHeartbeat& out);
  // The lowest over `actors` of the newest policy version in their chunks (0 if one sent none).
  std::uint64_t min_newest_chunk_version(const std::vector<std::uint32_t>& actors);
  double now_s() const { return seconds_since(start_); }
  // What the watch has seen, for a failing assertion's message: the newest snapshot, each
  // actor's newest chunk and each process's newest heartbeat, with their times.
  std::string describe();
  dds::Participant& participant() { return *participant_; }
  // A writer of trajectory chunks on the current participant, made at the first call after each
  // (re)opening (with DDS Security an observer may not publish, so only tests that write make
  // one): take it again after every call that may replace the participant.
  dds::Writer<msg::TrajectoryChunk>& chunk_writer() {
    if (!chunk_writer_) chunk_writer_ = participant_->make_writer<msg::TrajectoryChunk>();
    return *chunk_writer_;
  }
  // With DDS Security, a handshake of this watch's participant pending for
  // dds::Participant::kHandshakeStallS never completes (seen in the two-host security test on
  // 2026-12-05: the watch never authenticated one actor, so none of its chunks arrived), where a
  // new participant's does, as the service's actors replace theirs. Replaces the participant and
  // its readers when one of its handshakes has stalled; what was seen is kept. Returns whether
  // it did. Call it while waiting.
  bool replace_if_stalled();
  // On one host the SHM ports of a process killed with SIGKILL are reset by Fast DDS in every
  // process that uses them, and the watch's own participant can come out of that deaf to
  // processes that are running (seen on 2026-12-06: after a learner kill both actors replaced
  // their participants, and the watch heard actor 0's new one only after replacing its own; a
  // CI run failed so, the actors stepping on for 60 s). Replaces the participant when
  // one of `processes` (role, id), heard before, has sent no heartbeat for `silent_s` and the
  // participant is older than that; the services heartbeat every 0.2 s in every state. Returns
  // whether it did (counted in replacements() and shown by describe()). Call it while waiting.
  bool replace_if_unheard(const std::vector<std::pair<std::uint32_t, std::uint32_t>>& processes,
                          double silent_s);
  int replacements() const { return replacements_; }
  // Replaces the participant now (close, open, count and log it), for a test that finds it
  // deaf by other means (a process whose files show it running, unheard).
  void replace(const std::string& why);

 private:
  void open();
  void close();

  dds::ParticipantOptions options_;
  int replacements_ = 0;
  double opened_s_ = 0.0;  // when the current participant was ready (watch seconds)
  std::string replaced_why_;
  SteadyClock::time_point start_ = SteadyClock::now();
  std::unique_ptr<dds::Participant> participant_;
  std::unique_ptr<dds::Reader<msg::TrajectoryChunk>> chunk_reader_;
  std::unique_ptr<dds::Writer<msg::TrajectoryChunk>> chunk_writer_;
  std::unique_ptr<dds::Reader<msg::PolicySnapshot>> snapshot_reader_;
  std::unique_ptr<dds::Reader<msg::Heartbeat>> heartbeat_reader_;
  std::mutex mutex_;
  std::vector<SeenChunk> chunks_;
  std::vector<SeenSnapshot> snapshots_;
  std::map<std::pair<std::uint32_t, std::uint32_t>, SeenHeartbeat> heartbeats_;
};

// The YAML of the tiny-preset service runs of these tests: 16-step chunks, a 128-step prefill,
// replay ratio 4 (one update per 32 env steps, so that a loaded machine still trains often
// enough), a snapshot every 2 updates, metrics every second, fast announces and re-requests, no
// page writer (page_writer_test and service_test cover it). Tests change single keys with --set.
std::string tiny_service_config();

// Command line of a service executable (indrive-learner or indrive-actor) of a test run.
std::vector<std::string> service_args(const std::string& program,
                                      const std::filesystem::path& config,
                                      const std::filesystem::path& run_dir, int domain_id,
                                      const std::filesystem::path& profiles_file,
                                      const std::vector<std::string>& overrides = {});

}  // namespace indrive::testing
