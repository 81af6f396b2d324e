// Benchmark of the actor-learner service as real processes on this host over the single-host
// DDS profile: one indrive-learner and 1 or 2 indrive-actor processes, watched through the
// benchmark's own DDS participant. It prints
//   (a) aggregate env steps/s reaching the learner while it trains, with 1 and 2 actors, in
//       async mode (no rate limit) and rate-limited (the configured replay ratio);
//   (b) the snapshot size and the publish-to-use latency at the actors: from the learner's
//       write (the DDS source timestamp of the PolicySnapshot sample) to the actor's heartbeat
//       sent right after it loaded that version (its wall_time_s); both are the host's
//       system clock, so the difference is meaningful on one host only;
//   (c) chunk transport overhead: time the actors spent compressing and writing chunks as a
//       share of their run time (from each actor's stop line).
//
//   build/bin/learner_service_bench                  # tiny async + rate-limited, cpu rate-limited
//   build/bin/learner_service_bench --presets tiny   # about 2.5 minutes
//   build/bin/learner_service_bench --presets cpu --cpu-modes async,limited --actors 1
// A full run takes about 5 minutes on a quiet 2-core host (11 on a heavily loaded one): each
// scenario starts fresh processes, waits for training (and, rate-limited, for the learner to
// catch up with the prefill), then measures. Children get OMP_WAIT_POLICY=passive and
// GOMP_SPINCOUNT=100000 unless the environment sets them, as `indrive launch` does.
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <fastdds/dds/domain/DomainParticipant.hpp>
#include <fastdds/dds/subscriber/DataReader.hpp>
#include <fastdds/dds/subscriber/SampleInfo.hpp>
#include <fastdds/dds/subscriber/Subscriber.hpp>
#include <fastdds/dds/subscriber/qos/SubscriberQos.hpp>
#include <fastdds/dds/topic/Topic.hpp>
#include <fstream>
#include <map>
#include <mutex>
#include <nlohmann/json.hpp>
#include <optional>
#include <regex>
#include <sstream>
#include <thread>

#include "child_process.h"
#include "indrive/agent/agent_config.h"
#include "indrive/dds/participant.h"
#include "indrive/deploy/launch.h"
#include "indrive/msg/policyPubSubTypes.h"
#include "testing.h"

namespace indrive {
namespace {

namespace fs = std::filesystem;
namespace fdds = eprosima::fastdds::dds;
using namespace std::chrono_literals;
using Clock = std::chrono::steady_clock;

using testing::Child;
using testing::slurp;

std::string tail(const std::string& text, std::size_t chars = 1500) {
  return text.size() <= chars ? text : "..." + text.substr(text.size() - chars);
}

double seconds(const eprosima::fastrtps::rtps::Time_t& time) {
  return static_cast<double>(time.seconds()) + static_cast<double>(time.nanosec()) * 1e-9;
}

double unix_now_s() {
  return std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
}

struct Scenario {
  std::string preset;
  int actors = 1;
  bool async = true;
  int snapshot_every = 10;
  std::string name() const {
    return preset + (async ? " async" : " rate-limited") + ", " + std::to_string(actors) +
           (actors == 1 ? " actor" : " actors");
  }
};

// When and how big each snapshot was, as seen by the benchmark's own reader.
struct SnapshotSeen {
  double source_s = 0.0;    // learner's clock at write()
  double received_s = 0.0;  // this process's clock when the whole sample had arrived
  std::size_t bytes = 0;    // params blob
};

// One actor heartbeat announcing a newly loaded version.
struct Load {
  std::uint32_t actor = 0;
  std::uint64_t version = 0;
  double wall_s = 0.0;  // actor's clock right after loading
};

struct LearnerBeat {
  double wall_s = 0.0;
  std::uint64_t env_steps = 0;
  std::uint64_t updates = 0;
};

// Everything the benchmark hears on the wire during one scenario.
class Watcher : public fdds::DataReaderListener {
 public:
  Watcher(int domain, const std::string& profiles, std::string run_id)
      : run_id_(std::move(run_id)), participant_({.domain_id = domain, .profiles_file = profiles}) {
    heartbeats_ = participant_.make_reader<msg::Heartbeat>(
        [this](const msg::Heartbeat& beat) { on_heartbeat(beat); });
    // Snapshots through a plain Fast DDS reader: the wrapper hides SampleInfo, and the source
    // timestamp is the learner's write time.
    fdds::DomainParticipant* native = participant_.native();
    fdds::TypeSupport type(new msg::PolicySnapshotPubSubType());
    type.register_type(native);
    topic_ = native->create_topic(dds::TopicTraits<msg::PolicySnapshot>::kTopic,
                                  type.get_type_name(), fdds::TOPIC_QOS_DEFAULT);
    subscriber_ = native->create_subscriber(fdds::SUBSCRIBER_QOS_DEFAULT);
    if (topic_ == nullptr || subscriber_ == nullptr) throw std::runtime_error("snapshot topic");
    reader_ = subscriber_->create_datareader_with_profile(
        topic_, dds::TopicTraits<msg::PolicySnapshot>::kReaderProfile, this);
    if (reader_ == nullptr) throw std::runtime_error("cannot create the snapshot reader");
  }
  ~Watcher() override {
    reader_->set_listener(nullptr);
    subscriber_->delete_datareader(reader_);
    participant_.native()->delete_subscriber(subscriber_);
    participant_.native()->delete_topic(topic_);
    heartbeats_.reset();
  }

  void on_data_available(fdds::DataReader* reader) override {
    fdds::SampleInfo info;
    while (reader->take_next_sample(&snapshot_, &info) ==
           eprosima::fastrtps::types::ReturnCode_t::RETCODE_OK) {
      if (!info.valid_data || snapshot_.run_id() != run_id_) continue;
      std::lock_guard<std::mutex> lock(mutex_);
      snapshots_.try_emplace(snapshot_.version(),
                             SnapshotSeen{.source_s = seconds(info.source_timestamp),
                                          .received_s = unix_now_s(),
                                          .bytes = snapshot_.params().size()});
    }
  }

  void on_heartbeat(const msg::Heartbeat& beat) {
    if (beat.run_id() != run_id_) return;
    std::lock_guard<std::mutex> lock(mutex_);
    if (beat.role() == msg::ROLE_LEARNER) {
      learner_.push_back(
          {.wall_s = beat.wall_time_s(), .env_steps = beat.env_steps(), .updates = beat.updates()});
    } else if (beat.role() == msg::ROLE_ACTOR) {
      // The actor sends a heartbeat right after each swap, so the first one that carries a
      // version is the moment it started acting with it.
      auto& newest = actor_version_[beat.id()];
      if (beat.policy_version() > newest) {
        newest = beat.policy_version();
        loads_.push_back(
            {.actor = beat.id(), .version = beat.policy_version(), .wall_s = beat.wall_time_s()});
      }
    }
  }

  std::optional<LearnerBeat> newest_learner() {
    std::lock_guard<std::mutex> lock(mutex_);
    if (learner_.empty()) return std::nullopt;
    return learner_.back();
  }
  std::vector<LearnerBeat> learner_beats() {
    std::lock_guard<std::mutex> lock(mutex_);
    return learner_;
  }
  std::map<std::uint64_t, SnapshotSeen> snapshots() {
    std::lock_guard<std::mutex> lock(mutex_);
    return snapshots_;
  }
  std::vector<Load> loads() {
    std::lock_guard<std::mutex> lock(mutex_);
    return loads_;
  }

 private:
  std::string run_id_;
  dds::Participant participant_;
  std::unique_ptr<dds::Reader<msg::Heartbeat>> heartbeats_;
  fdds::Topic* topic_ = nullptr;
  fdds::Subscriber* subscriber_ = nullptr;
  fdds::DataReader* reader_ = nullptr;
  msg::PolicySnapshot snapshot_;  // reused between samples
  std::mutex mutex_;
  std::vector<LearnerBeat> learner_;
  std::map<std::uint32_t, std::uint64_t> actor_version_;
  std::vector<Load> loads_;
  std::map<std::uint64_t, SnapshotSeen> snapshots_;
};

// What one actor's stop line says about its time.
struct ActorTime {
  double total_s = 0.0;
  double wait_s = 0.0;
  double publish_s = 0.0;
  std::uint64_t chunks = 0;
};

std::optional<ActorTime> parse_stop_line(const std::string& log) {
  static const std::regex line(
      R"(stops: \d+ steps, (\d+) chunks, .* waited ([0-9.eE+-]+) s of ([0-9.eE+-]+) s, )"
      R"(publishing took ([0-9.eE+-]+) s)");
  std::smatch match;
  if (!std::regex_search(log, match, line)) return std::nullopt;
  return ActorTime{.total_s = std::stod(match[3]),
                   .wait_s = std::stod(match[2]),
                   .publish_s = std::stod(match[4]),
                   .chunks = std::stoull(match[1])};
}

struct Result {
  Scenario scenario;
  std::string error;  // empty: measured
  double window_s = 0.0;
  double env_steps_per_s = 0.0;
  double updates_per_s = 0.0;
  double replay_ratio = 0.0;      // inside the window
  double run_replay_ratio = 0.0;  // the learner's figure over the whole run
  double publish_share = 0.0;
  double wait_share = 0.0;
  std::uint64_t chunks = 0;
  std::vector<double> use_latency_ms;       // publish -> in use at an actor
  std::vector<double> delivery_latency_ms;  // publish -> received by the benchmark's reader
  std::size_t snapshot_bytes = 0;
  std::size_t snapshots = 0;
};

struct Options {
  fs::path bin_dir = INDRIVE_BIN_DIR;
  fs::path profile = testing::source_path("deploy/dds/single_host.xml");
  std::vector<std::string> presets = {"tiny", "cpu"};
  double window_s = 15.0;
  double cpu_window_s = 30.0;
  fs::path keep_logs;  // empty: logs go with the temporary folder
  std::vector<int> actor_counts = {1, 2};
  std::vector<std::string> modes = {"async", "limited"};
  // cpu: rate-limited only by default. Async cpu actors take every core from a learner whose
  // updates take seconds, which on a small host starves it (and the snapshot latency then
  // measures that starvation).
  std::vector<std::string> cpu_modes = {"limited"};
};

// Service settings of every scenario (written into its config below).
constexpr double kReplayRatio = 32.0;
constexpr double kChunkLength = 64.0;
constexpr double kSlackSteps = 64.0;  // learner.allowance_slack's default

std::string config_text(const Scenario& scenario) {
  std::ostringstream text;
  text << "preset: " << scenario.preset << R"(
run:
  seed: 5
env:
  densities: [10]
  time_limit_steps: 400
actor:
  chunk_length: 64
  heartbeat_s: 0.5
agent:
  replay:
    prefill: 256
    capacity: 50000
learner:
  async: )"
       << (scenario.async ? "true" : "false") << R"(
  replay_ratio: 32
  snapshot_every: )"
       << scenario.snapshot_every << R"(
  log_interval_s: 1
  announce_s: 1
  checkpoint_minutes: 600
)";
  return text.str();
}

double percentile(std::vector<double> values, double fraction) {
  if (values.empty()) return 0.0;
  std::sort(values.begin(), values.end());
  const auto index =
      static_cast<std::size_t>(fraction * static_cast<double>(values.size() - 1) + 0.5);
  return values[std::min(index, values.size() - 1)];
}

Result run_scenario(const Scenario& scenario, const Options& options, int domain, double window_s) {
  Result result{.scenario = scenario};
  testing::TempDir dir("indrive-service-bench");
  const std::string run_id = "bench-" + scenario.preset + "-" + std::to_string(scenario.actors) +
                             (scenario.async ? "-async" : "-limited");
  const fs::path run_dir = dir.path() / "runs" / run_id;
  const fs::path config = dir.path() / "bench.yaml";
  std::ofstream(config) << config_text(scenario);
  const fs::path logs = options.keep_logs.empty() ? dir.path() : options.keep_logs / run_id;
  fs::create_directories(logs);

  auto args = [&](const std::string& program) {
    return std::vector<std::string>{(options.bin_dir / program).string(),
                                    "--config",
                                    config.string(),
                                    "--run-dir",
                                    run_dir.string(),
                                    "--domain",
                                    std::to_string(domain),
                                    "--dds-profile",
                                    options.profile.string()};
  };
  auto all_logs = [&] {
    std::string text;
    for (const auto& entry : fs::directory_iterator(logs)) {
      if (entry.path().extension() == ".log") {
        text += "----- " + entry.path().filename().string() + "\n" + tail(slurp(entry.path()));
      }
    }
    return text;
  };

  Watcher watcher(domain, options.profile.string(), run_id);
  auto learner = std::make_unique<Child>(args("indrive-learner"), logs / "learner.log");
  std::vector<std::unique_ptr<Child>> actors;
  for (int id = 0; id < scenario.actors; ++id) {
    auto argv = args("indrive-actor");
    argv.insert(argv.end(), {"--id", std::to_string(id)});
    actors.push_back(
        std::make_unique<Child>(argv, logs / ("actor-" + std::to_string(id) + ".log")));
  }
  auto alive = [&] {
    if (!learner->running()) return false;
    return std::all_of(actors.begin(), actors.end(), [](auto& actor) { return actor->running(); });
  };

  // Warm-up: processes start, the replay prefills, training begins; then a short settle so
  // the window sees steady state.
  const auto warmup_end = Clock::now() + 180s;
  while (Clock::now() < warmup_end) {
    if (!alive()) {
      result.error = "a process exited during warm-up\n" + all_logs();
      return result;
    }
    const auto beat = watcher.newest_learner();
    if (beat && beat->updates > 0) break;
    std::this_thread::sleep_for(100ms);
  }
  if (const auto beat = watcher.newest_learner(); !beat || beat->updates == 0) {
    result.error = "training did not start within 180 s\n" + all_logs();
    return result;
  }
  // A rate-limited learner first owes the updates of the prefill; the window starts once it
  // has caught up (its backlog no larger than what the allowance's slack and one chunk in
  // flight allow), so that it sees the steady state the replay ratio holds.
  const agent::AgentConfig sizes = agent::preset(scenario.preset);
  const double steps_per_update = sizes.replay.batch * sizes.replay.length;
  if (!scenario.async) {
    const double backlog_limit = (kSlackSteps + kChunkLength) * kReplayRatio / steps_per_update + 2;
    const auto caught_up_end = Clock::now() + 180s;
    while (Clock::now() < caught_up_end) {
      if (!alive()) {
        result.error = "a process exited while the learner caught up\n" + all_logs();
        return result;
      }
      const LearnerBeat beat = *watcher.newest_learner();
      const double due = static_cast<double>(beat.env_steps) * kReplayRatio / steps_per_update;
      if (due - static_cast<double>(beat.updates) <= backlog_limit) break;
      std::this_thread::sleep_for(100ms);
    }
  }
  std::this_thread::sleep_for(2s);
  // (a) throughput from the learner's own heartbeats: it sends them between updates, so the
  // window runs from the newest one at its start to the first one at least window_s later.
  // Steps arrive a chunk at a time, so the window also waits (up to 2 minutes more) for a few
  // chunks: a slow rate-limited learner lets only one chunk through every few updates.
  const LearnerBeat first = *watcher.newest_learner();
  std::optional<LearnerBeat> last;
  const auto window_deadline = Clock::now() + std::chrono::duration<double>(window_s) + 120s;
  while (Clock::now() < window_deadline) {
    if (!alive()) {
      result.error = "a process exited during the measurement\n" + all_logs();
      return result;
    }
    const LearnerBeat newest = *watcher.newest_learner();
    if (newest.wall_s - first.wall_s >= window_s) {
      last = newest;
      if (newest.env_steps - first.env_steps >= 3 * kChunkLength) break;
    }
    std::this_thread::sleep_for(100ms);
  }
  if (!last) {
    result.error = "no learner heartbeat closed the window\n" + all_logs();
    return result;
  }
  result.window_s = last->wall_s - first.wall_s;
  const auto steps = static_cast<double>(last->env_steps - first.env_steps);
  const auto updates = static_cast<double>(last->updates - first.updates);
  result.env_steps_per_s = steps / result.window_s;
  result.updates_per_s = updates / result.window_s;
  // Replayed steps per env step inside the window (batch x length replayed per update).
  if (steps > 0.0) result.replay_ratio = updates * steps_per_update / steps;

  // (c) the actors' own time accounting, printed when they stop.
  for (auto& actor : actors) actor->stop(30s);
  double total_s = 0.0, wait_s = 0.0, publish_s = 0.0;
  for (int id = 0; id < scenario.actors; ++id) {
    const auto time = parse_stop_line(slurp(logs / ("actor-" + std::to_string(id) + ".log")));
    if (!time) {
      result.error = "actor " + std::to_string(id) + " wrote no stop line\n" + all_logs();
      return result;
    }
    total_s += time->total_s;
    wait_s += time->wait_s;
    publish_s += time->publish_s;
    result.chunks += time->chunks;
  }
  result.publish_share = total_s > 0.0 ? publish_s / total_s : 0.0;
  result.wait_share = total_s > 0.0 ? wait_s / total_s : 0.0;
  learner->stop(60s);

  // The learner's own replay-ratio figure (whole run, prefill included) from its metrics.
  std::ifstream metrics(run_dir / "metrics.jsonl");
  std::string line, newest;
  while (std::getline(metrics, line)) {
    if (!line.empty()) newest = line;
  }
  if (!newest.empty())
    result.run_replay_ratio = nlohmann::json::parse(newest).value("replay_ratio", 0.0);

  // (b) snapshot size and latencies; versions the benchmark's reader missed are skipped.
  const auto snapshots = watcher.snapshots();
  result.snapshots = snapshots.size();
  if (!snapshots.empty()) result.snapshot_bytes = snapshots.rbegin()->second.bytes;
  for (const auto& [version, seen] : snapshots) {
    result.delivery_latency_ms.push_back((seen.received_s - seen.source_s) * 1000.0);
  }
  for (const Load& load : watcher.loads()) {
    const auto seen = snapshots.find(load.version);
    if (seen == snapshots.end()) continue;
    result.use_latency_ms.push_back((load.wall_s - seen->second.source_s) * 1000.0);
  }
  if (!options.keep_logs.empty())
    fs::copy(config, logs / "bench.yaml", fs::copy_options::overwrite_existing);
  return result;
}

std::string latency_text(const std::vector<double>& values) {
  if (values.empty()) return "n/a";
  char text[160];
  std::snprintf(text, sizeof text, "median %.1f ms, p90 %.1f ms, max %.1f ms (n=%zu)",
                percentile(values, 0.5), percentile(values, 0.9),
                *std::max_element(values.begin(), values.end()), values.size());
  return text;
}

void print_table(const std::vector<Result>& results, const Options& options) {
  std::printf(
      "\nService benchmark: indrive-learner + indrive-actor processes on this host, DDS "
      "profile %s,\ntown01 at traffic density 10, %u hardware threads, OMP_WAIT_POLICY=%s. Env "
      "steps/s are "
      "steps received by the learner\nwhile it trains (its heartbeats, over the "
      "window); rate-limited runs keep replay ratio 32.\n\n",
      options.profile.filename().c_str(), std::thread::hardware_concurrency(),
      std::getenv("OMP_WAIT_POLICY"));
  std::printf("%-28s %8s %12s %10s %10s %8s %8s %10s %8s\n", "scenario", "window_s", "env_steps/s",
              "per_actor", "updates/s", "ratio_w", "ratio_r", "publish_%", "wait_%");
  for (const Result& result : results) {
    if (!result.error.empty()) {
      std::printf("%-28s FAILED (see below)\n", result.scenario.name().c_str());
      continue;
    }
    std::printf("%-28s %8.1f %12.1f %10.1f %10.3f %8.2f %8.2f %10.2f %8.1f\n",
                result.scenario.name().c_str(), result.window_s, result.env_steps_per_s,
                result.env_steps_per_s / result.scenario.actors, result.updates_per_s,
                result.replay_ratio, result.run_replay_ratio, 100.0 * result.publish_share,
                100.0 * result.wait_share);
  }
  std::printf(
      "\nratio_w: replayed steps per env step inside the window; ratio_r: the "
      "learner's figure over the whole run (prefill included).");
  std::printf(
      "\npublish_%%: time the actors spent compressing and writing TrajectoryChunks, as a "
      "share of their run time\n(ActorStats publish_s / total_s, summed over actors); "
      "wait_%%: time waiting at the StepAllowance.\n\n");
  std::printf(
      "Snapshots (publish = the learner's DDS write; use = the actor's heartbeat right "
      "after loading it):\n");
  for (const Result& result : results) {
    if (!result.error.empty() || result.snapshots == 0) continue;
    std::printf("  %-28s %zu snapshots of %.2f MB\n", result.scenario.name().c_str(),
                result.snapshots, static_cast<double>(result.snapshot_bytes) / 1.0e6);
    std::printf("    publish -> in use at an actor:   %s\n",
                latency_text(result.use_latency_ms).c_str());
    std::printf("    publish -> received (transport): %s\n",
                latency_text(result.delivery_latency_ms).c_str());
  }
  for (const Result& result : results) {
    if (result.error.empty()) continue;
    std::printf("\n%s FAILED: %s\n", result.scenario.name().c_str(), result.error.c_str());
  }
}

}  // namespace
}  // namespace indrive

int main(int argc, char** argv) {
  using namespace indrive;
  Options options;
  CLI::App app{
      "learner_service_bench: throughput, snapshot latency and chunk overhead of the "
      "service as real processes"};
  app.add_option("--bin-dir", options.bin_dir, "folder with indrive-learner and indrive-actor")
      ->check(CLI::ExistingDirectory);
  app.add_option("--dds-profile", options.profile, "Fast DDS profiles file")
      ->check(CLI::ExistingFile);
  app.add_option("--presets", options.presets, "presets to run (tiny, cpu)")->delimiter(',');
  app.add_option("--window-s", options.window_s, "measurement window of tiny runs (seconds)");
  app.add_option("--cpu-window-s", options.cpu_window_s,
                 "measurement window of cpu runs (seconds; its updates are slow)");
  app.add_option("--keep-logs", options.keep_logs, "copy the processes' logs to this folder");
  app.add_option("--actors", options.actor_counts, "actor counts to run")->delimiter(',');
  app.add_option("--modes", options.modes, "tiny preset: async, limited")->delimiter(',');
  app.add_option("--cpu-modes", options.cpu_modes, "cpu preset: async, limited")->delimiter(',');
  CLI11_PARSE(app, argc, argv);

  // The children get the profile by flag; an inherited default would make them refuse it.
  ::unsetenv(indrive::dds::kProfilesEnvVar);
  // As `indrive launch` does: idle OpenMP threads sleep, after a short spin, instead of spinning
  // on cores the other processes need. OMP_WAIT_POLICY=active or GOMP_SPINCOUNT=0 in the
  // environment measures the difference.
  indrive::deploy::set_openmp_wait_defaults();
  std::vector<Scenario> scenarios;
  auto wanted = [&](const std::string& preset, const char* mode) {
    const auto& modes = preset == "cpu" ? options.cpu_modes : options.modes;
    return std::find(modes.begin(), modes.end(), mode) != modes.end();
  };
  for (const auto& preset : options.presets) {
    // cpu updates take seconds: a snapshot after each, so the window holds enough of them.
    const int snapshot_every = preset == "cpu" ? 1 : 10;
    for (bool async : {true, false}) {
      if (!wanted(preset, async ? "async" : "limited")) continue;
      for (int actors : options.actor_counts) {
        scenarios.push_back(
            {.preset = preset, .actors = actors, .async = async, .snapshot_every = snapshot_every});
      }
    }
  }

  const int domain = indrive::testing::unique_domain_id();
  std::vector<Result> results;
  bool failed = false;
  for (const Scenario& scenario : scenarios) {
    const double window = scenario.preset == "cpu" ? options.cpu_window_s : options.window_s;
    std::fprintf(stderr, "[bench] %s: measuring %.0f s after warm-up\n", scenario.name().c_str(),
                 window);
    try {
      results.push_back(run_scenario(scenario, options, domain, window));
    } catch (const std::exception& error) {
      results.push_back({.scenario = scenario, .error = error.what()});
    }
    failed = failed || !results.back().error.empty();
  }
  print_table(results, options);
  return failed ? 1 : 0;
}
