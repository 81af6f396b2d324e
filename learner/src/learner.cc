#include "indrive/learner/learner.h"

#include <algorithm>
#include <chrono>
#include <mutex>
#include <nlohmann/json.hpp>
#include <optional>
#include <sstream>
#include <thread>

#include "indrive/agent/agent.h"
#include "indrive/agent/rate_limiter.h"
#include "indrive/agent/snapshot_file.h"
#include "indrive/basics/check.h"
#include "indrive/basics/episode_csv.h"
#include "indrive/basics/log.h"
#include "indrive/basics/run_dir.h"
#include "indrive/basics/stopwatch.h"
#include "indrive/dds/participant.h"
#include "indrive/dds/security.h"
#include "indrive/dds/shm_sweeper.h"
#include "indrive/learner/evaluation_tally.h"
#include "indrive/learner/ingest.h"
#include "indrive/learner/learner_config.h"
#include "indrive/learner/pacing.h"
#include "indrive/learner/snapshot_publisher.h"
#include "indrive/learner/training_episodes.h"
#include "indrive/nn/kernels.h"
#include "indrive/service/training_metrics.h"

namespace indrive::learner {
namespace fs = std::filesystem;
namespace {

using Clock = std::chrono::steady_clock;
// Policy versions reserved before they are published (VersionReservation).
constexpr std::string_view kVersionReserveFile = "policy_versions_reserved";

}  // namespace

struct Learner::Impl {
  explicit Impl(const service::ServiceConfig& service)
      : config(service),
        settings(learner_config(service.config())),
        agent_config(service.training_agent("learner")),
        run(RunDir::open_or_create(service.run_dir().parent_path().empty()
                                       ? fs::path(".")
                                       : service.run_dir().parent_path(),
                                   service.run_id())),
        checkpoints(run.checkpoints(), settings.checkpoint_keep, "learner", settings.checkpoint_s),
        versions(run.checkpoints() / kVersionReserveFile),
        replay(replay_options(agent_config)),
        rate({.replay_ratio = settings.replay_ratio,
              .steps_per_update =
                  static_cast<std::int64_t>(agent_config.replay.batch) * agent_config.replay.length,
              .prefill = agent_config.replay.prefill,
              .slack = settings.allowance_slack,
              .async = settings.async}),
        chunks({.run_id = service.run_id(),
                .height = agent_config.world_model.image,
                .width = agent_config.world_model.image,
                .phase = service.wire_phase(),
                .with_rewards = agent_config.phase != agent::Phase::kPretrain}),
        metrics(run.metrics_path()),
        train_episodes(run.train_episodes_path(), {.method = agent::method_label(agent_config),
                                                   .task = agent::task_label(agent_config),
                                                   .train_seed = static_cast<int>(settings.seed)}) {
    config.config().write_yaml(run.config_path());

    resume();
    config.note_agent_precision(*agent, "learner");
    // A final snapshot file left by an earlier end of this run (one resumed with a larger
    // budget) is not this run's end: evaluators must not take it.
    std::error_code removed_error;
    if (std::filesystem::remove(final_snapshot_path(run.path()), removed_error)) {
      INDRIVE_LOG(kInfo, "learner") << "removed the final snapshot file of an earlier end of "
                                       "this run; the run's new end writes it again";
    }
    fill_target = std::min<std::int64_t>(agent_config.replay.prefill, agent_config.replay.capacity);
    // Actors may always run until replay holds the prefill again; a restored replay needs none.
    fill_floor = stats.counters.env_steps + std::max<std::int64_t>(0, fill_target - replay.size());

    endpoints = std::make_unique<dds::EndpointSet>(service.participant_options("learner"));
    publisher.emplace(*endpoints, config.run_id(), settings.snapshot_hold_s);
    pacer.emplace(*endpoints, config.run_id());
    endpoints->reader<msg::TrajectoryChunk>(
        [this](const msg::TrajectoryChunk& chunk) { chunks.offer(chunk); });
    endpoints->reader<msg::EpisodeResult>(
        [this](const msg::EpisodeResult& result) { on_result(result); });
    // A resumed learner hands out its restored policy at once, under a new version.
    if (stats.counters.updates > 0) publish_snapshot();
    publish_pacing(/*force=*/true);
    INDRIVE_LOG(kInfo, "learner") << "learner of run '" << config.run_id() << "' ready (epoch "
                                  << stats.counters.learner_epoch << ", "
                                  << stats.counters.env_steps << " env steps, "
                                  << stats.counters.updates << " updates, policy v"
                                  << stats.counters.policy_version << "); architecture '"
                                  << service::architecture_descriptor(agent_config) << "'";
    INDRIVE_LOG(kInfo, "learner") << nn::kernel_report();
  }

  // The readers' callbacks use the queues and counters: the endpoints go first, then the
  // publisher and the pacer that wrote on them.
  ~Impl() {
    endpoints.reset();
    publisher.reset();
    pacer.reset();
  }

  static agent::ReplayOptions replay_options(const agent::AgentConfig& agent_config) {
    return {.capacity = agent_config.replay.capacity,
            .height = agent_config.world_model.image,
            .width = agent_config.world_model.image,
            .has_rewards = agent_config.phase != agent::Phase::kPretrain,
            .seed = agent_config.replay.seed + agent_config.seed};
  }

  // Restores the newest intact checkpoint of this run, or a finetune's initial checkpoint
  // (start_run).
  void resume() {
    RunStart start = start_run(checkpoints.files().list(), settings.init_checkpoint, agent_config,
                               replay_options(agent_config), config.run_id());
    agent = start.restored.agent ? std::move(start.restored.agent)
                                 : std::make_unique<agent::Agent>(agent_config);
    stats.counters = start.restored.counters;
    if (start.from == StartedFrom::kCheckpoint) {
      replay = std::move(*start.restored.replay);
      stats.restored_replay_steps = replay.size();
      stats.resumed_from = start.restored.file;
      stats.skipped_checkpoints = start.restored.skipped;
      checkpoints.resumed_from(start.restored.file);
    }
    // Snapshots published after the newest checkpoint used versions up to the reserved mark.
    stats.counters.policy_version = std::max(stats.counters.policy_version, versions.reserved());
  }

  // Writes a checkpoint (CheckpointWriter); returns whether it was written. `final`: the one at
  // exit, which has no next try.
  bool save_checkpoint(bool final = false) {
    return checkpoints.save(stats.counters, agent->checkpoint_bytes(), replay.to_bytes(),
                            replay.size(), final);
  }

  void on_result(const msg::EpisodeResult& result) {
    if (dds::validate(result, config.run_id()) != dds::DropReason::kOk) return;
    if (result.sender_role() == msg::ROLE_EVALUATOR) {
      evaluations.add(result);
      return;
    }
    if (result.sender_role() != msg::ROLE_ACTOR) return;
    std::lock_guard<std::mutex> lock(results_mutex);
    ++interval_episodes;
    interval_successes += result.success() ? 1 : 0;
    episode_stats.add(result.steps(), result.reach_segments());
    train_episodes.write(dds::episode_fields(result));  // one row per finished episode
  }

  // Moves queued chunks into replay; returns whether there were any.
  bool drain() {
    const ChunkQueue::Drained drained = chunks.drain_into(replay, stats.counters.policy_version);
    stats.counters.env_steps += drained.steps;
    stats.chunks += drained.chunks;
    stats.sequence_gaps += drained.sequence_gaps;
    interval_lag_sum += drained.lag_sum;
    interval_chunks += drained.chunks;
    return drained.chunks > 0;
  }

  bool ready_to_train() const {
    if (replay.size() < fill_target || replay.num_windows(agent_config.replay.length) == 0) {
      return false;
    }
    if (rate.options().async) return true;
    return stats.counters.updates < rate.updates_due(stats.counters.env_steps);
  }

  void train_one() {
    agent::SequenceBatch batch =
        replay.sample(agent_config.replay.batch, agent_config.replay.length);
    try {
      last_metrics = agent->train_step(batch);
      const agent::TrainMetrics timing = agent->last_timing().as_metrics();
      last_metrics.insert(last_metrics.end(), timing.begin(), timing.end());
    } catch (const std::exception& error) {
      // A failed update is counted and skipped; the run goes on.
      ++stats.failed_updates;
      INDRIVE_LOG(kError, "learner") << "update failed and was skipped: " << error.what();
    }
    ++stats.counters.updates;
    // The loop publishes it right after this update, or once the last reached every reader.
    if (stats.counters.updates % settings.snapshot_every == 0) publisher->mark_due();
  }

  void publish_snapshot() {
    msg::PolicySnapshot snapshot;
    versions.reserve(stats.counters.policy_version + 1);
    snapshot.version(++stats.counters.policy_version);
    snapshot.preset(agent_config.preset);
    snapshot.architecture(service::architecture_descriptor(agent_config));
    snapshot.heads(msg::HEAD_ENCODER | msg::HEAD_RSSM |
                   (agent_config.phase == agent::Phase::kPretrain ? msg::HEAD_EXPLORATION_ACTOR
                                                                  : msg::HEAD_TASK_ACTOR));
    snapshot.phase(config.wire_phase());
    snapshot.env_steps(static_cast<std::uint64_t>(stats.counters.env_steps));
    snapshot.updates(static_cast<std::uint64_t>(stats.counters.updates));
    snapshot.params(agent->snapshot());
    publisher->publish(std::move(snapshot), done);
    ++stats.snapshots_published;
  }

  std::uint64_t allowance() const {
    std::uint64_t allowed = rate.allowance(stats.counters.updates, fill_floor);
    if (settings.budget_env_steps > 0) {
      allowed =
          std::min<std::uint64_t>(allowed, static_cast<std::uint64_t>(settings.budget_env_steps));
    }
    return allowed;
  }

  // The allowance and the heartbeat (Pacer says when they go out).
  void publish_pacing(bool force) {
    pacer->publish({.allowed = allowance(),
                    .env_steps = stats.counters.env_steps,
                    .updates = stats.counters.updates,
                    .policy_version = stats.counters.policy_version,
                    .learner_epoch = stats.counters.learner_epoch,
                    .replay_ratio = rate.options().replay_ratio,
                    .dropped_chunks = chunks.drops().dropped(),
                    .done = done},
                   force);
  }

  service::TrainingProgress progress_now() const {
    return {.env_steps = stats.counters.env_steps,
            .updates = stats.counters.updates,
            .policy_version = stats.counters.policy_version,
            .learner_epoch = stats.counters.learner_epoch,
            .replay_size = replay.size(),
            .steps_per_update = rate.options().steps_per_update,
            .phase = agent_config.phase};
  }

  // A metrics line and a console line when one is due (or `force`).
  void log_metrics(bool force = false) {
    const service::TrainingProgress now = progress_now();
    if (!force && !interval.due(now, settings.log_interval_s, settings.log_every_env_steps)) return;
    std::uint64_t episodes = 0, successes = 0;
    auto episode_record = nlohmann::json::object();  // length and reach of the actors' episodes
    {
      std::lock_guard<std::mutex> lock(results_mutex);
      std::swap(episodes, interval_episodes);
      std::swap(successes, interval_successes);
      episode_stats.write(episode_record);
    }
    stats.episodes += episodes;
    const double lag = interval_chunks > 0 ? interval_lag_sum / interval_chunks : 0.0;
    const dds::DropCounters& drops = chunks.drops();
    nlohmann::json record = interval.fields(now);
    record.update({{"policy_lag", lag},
                   {"replay_added", replay.total_added()},
                   {"snapshots_published", stats.snapshots_published},
                   {"snapshot_requests", stats.snapshot_requests},
                   {"snapshots_held", publisher->holds()},
                   {"snapshot_holds_expired", publisher->holds_expired()},
                   {"chunks", stats.chunks},
                   {"replay_actors", chunks.actors()},
                   {"dropped_chunks", drops.dropped()},
                   {"dropped_wrong_run", drops.count(dds::DropReason::kWrongRun)},
                   {"dropped_bad_checksum", drops.count(dds::DropReason::kBadChecksum)},
                   {"dropped_bad_shape", drops.count(dds::DropReason::kBadShape)},
                   {"dropped_wrong_schema", drops.count(dds::DropReason::kWrongSchema)},
                   {"dropped_duplicate", drops.count(dds::DropReason::kDuplicate)},
                   {"dropped_undecodable", dds::undecodable_samples()},
                   {"sequence_gaps", stats.sequence_gaps},
                   {"failed_updates", stats.failed_updates},
                   {"checkpoints", checkpoints.written()},
                   {"checkpoint_failures", checkpoints.failures()},
                   {"episodes", episodes}});
    if (episodes > 0) record["episode_success_rate"] = static_cast<double>(successes) / episodes;
    record.update(episode_record);
    evaluations.write_new(record);
    for (const auto& [name, value] : last_metrics) record[name] = value;
    metrics.write(record);

    std::ostringstream line;
    line.precision(3);
    line << interval.console_head(now) << " | ratio " << record["replay_ratio"].get<double>()
         << " | policy v" << now.policy_version << " lag " << lag << " | dropped "
         << drops.dropped();
    int shown = 0;
    for (const auto& [name, value] : last_metrics) {
      if (name.find("loss") == std::string::npos || shown++ >= 4) continue;
      line << " | " << name << " " << value;
    }
    if (progress) progress(line.str());
    interval.restart(now);
    interval_lag_sum = 0.0;
    interval_chunks = 0;
  }

  // An actor or evaluator ended by a signal leaves its Fast DDS shared-memory segment in
  // /dev/shm (dds/shm_sweeper.h). The launcher removes them for the processes it runs; the
  // learner does the same every minute, so that runs whose processes are started by hand or by
  // compose, in containers sharing the learner's /dev/shm, do not fill it crash by crash.
  void sweep_shared_memory() {
    if (!sweeper || Clock::now() < next_sweep) return;
    next_sweep = Clock::now() + std::chrono::seconds(60);
    const dds::SweepResult swept = sweeper->sweep(Clock::now());
    if (swept.removed > 0) {
      INDRIVE_LOG(kInfo, "learner")
          << "removed " << swept.removed << " shared-memory segment(s) of ended processes ("
          << static_cast<double>(swept.removed_bytes) / (1 << 20) << " MiB)";
    }
  }

  // The run: the loop until the budget or the stop, then its end.
  int run_loop(const std::atomic<bool>& stop) {
    train_until(stop);
    return finish();
  }

  // Each turn: an update when the replay ratio allows one, the chunks that came, the pacing, the
  // snapshot when due, late joiners' requests, announces, metrics, the shared-memory sweep and
  // the checkpoint when due. Sets `done` when the budget is spent.
  void train_until(const std::atomic<bool>& stop) {
    if (fs::is_directory("/dev/shm")) sweeper.emplace("/dev/shm");
    next_sweep = Clock::now();
    interval.restart(progress_now());
    while (!stop.load()) {
      bool worked = false;
      if (ready_to_train()) {
        train_one();
        worked = true;
      }
      // Chunks that arrived during the update are counted before the pacing goes out: a
      // heartbeat with an older count would make each actor forget the steps it sent meanwhile
      // and take them again, running ahead of the replay ratio on a slow or loaded machine.
      worked = drain() || worked;
      publish_pacing(false);
      if (publisher->take_due(stats.counters.updates)) publish_snapshot();
      if (publisher->serve_request(done)) ++stats.snapshot_requests;
      if (publisher->seconds_since_announce() >= settings.announce_s) publisher->announce(done);
      log_metrics();
      sweep_shared_memory();
      if (checkpoints.seconds_since_save() >= settings.checkpoint_s) save_checkpoint();
      // The budget ends the run once the updates it is owed are done.
      if (settings.budget_env_steps > 0 && stats.counters.env_steps >= settings.budget_env_steps &&
          (rate.options().async || !ready_to_train())) {
        done = true;
        break;
      }
      if (!worked) std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
  }

  // The run's end: what was received is stored, the last snapshot published and kept as a file,
  // the final checkpoint written, the final announce made reliably. Returns the exit code.
  int finish() {
    // Chunks already received are stored, so the final checkpoint keeps them.
    drain();
    // At the budget's end a run that never published a snapshot (snapshot_every above its
    // updates) publishes its parameters, so evaluators of a short run have a policy. Only then:
    // a snapshot written just before the learner exits can be lost to readers still fetching
    // it, and the newest periodic snapshot is the run's final policy otherwise. The learner
    // lingers briefly so readers can fetch it.
    // A snapshot still held for a slow reader goes now too: it is the run's final policy.
    if (done && stats.counters.updates > 0 && (!publisher->newest() || publisher->due())) {
      publish_snapshot();
      INDRIVE_LOG(kInfo, "learner") << "final snapshot v" << stats.counters.policy_version << " at "
                                    << stats.counters.updates << " updates";
      std::this_thread::sleep_for(std::chrono::seconds(2));
    }
    // The run's final policy as <run>/final-snapshot.params, so it can be evaluated without the
    // learner: by `indrive-actor --evaluate --snapshot FILE`, and by an evaluator on this host
    // that waited for the final snapshot but received none over DDS (one restarted after the
    // learner ended, or one deaf to it; evaluator.cc). Written before the final announce.
    if (done) publisher->write_final_file(final_snapshot_path(run.path()), agent_config);
    // A final checkpoint that cannot be written loses the run's work since the previous one:
    // the exit code says so (indrive launch restarts a learner that exits non-zero, which then
    // resumes from that previous checkpoint).
    int code = 0;
    if ((stats.counters.env_steps > 0 || stats.counters.updates > 0) &&
        !save_checkpoint(/*final=*/true)) {
      code = 1;
      INDRIVE_LOG(kError, "learner")
          << "the final checkpoint could not be written (see the error above), so the learner "
             "exits with code 1: a restart resumes from "
          << (checkpoints.latest().empty() ? "nothing (this run has no checkpoint)"
                                           : checkpoints.latest().string())
          << " and what was trained and received after it is lost; free disk space before the "
             "run continues";
    }
    versions.release(stats.counters.policy_version);
    log_metrics(/*force=*/true);
    publish_pacing(true);
    if (done) publisher->announce_final(done);
    INDRIVE_LOG(kInfo, "learner") << (done ? "budget reached" : "stopped") << ": "
                                  << stats.counters.env_steps << " env steps, "
                                  << stats.counters.updates << " updates, policy v"
                                  << stats.counters.policy_version << ", chunks " << stats.chunks
                                  << ", " << chunks.drops().summary() << ", checkpoints "
                                  << checkpoints.written() << " (" << checkpoints.failures()
                                  << " failed)";
    return code;
  }

  const service::ServiceConfig& config;
  const LearnerConfig settings;  // the learner.* and run.* keys, read once
  agent::AgentConfig agent_config;
  RunDir run;
  CheckpointWriter checkpoints;
  VersionReservation versions;  // policy versions reserved on disk before they are published
  std::unique_ptr<agent::Agent> agent;  // set by resume()
  agent::ReplayBuffer replay;
  agent::RateLimiter rate;
  ChunkQueue chunks;  // chunks on their way into the replay
  MetricsLog metrics;
  EvaluationTally evaluations;                      // evaluators' results, on the metrics lines
  std::optional<dds::SharedMemorySweeper> sweeper;  // of /dev/shm, when there is one
  Clock::time_point next_sweep{};
  std::int64_t fill_target = 0;
  std::int64_t fill_floor = 0;
  bool done = false;

  // DDS: the endpoint set owns every reader and writer; the publisher and the pacer write on it.
  std::unique_ptr<dds::EndpointSet> endpoints;
  std::optional<SnapshotPublisher> publisher;
  std::optional<Pacer> pacer;

  std::mutex results_mutex;
  std::uint64_t interval_episodes = 0, interval_successes = 0;  // under results_mutex
  EpisodeStats episode_stats;                                   // under results_mutex
  TrainingEpisodes train_episodes;  // train-episodes.csv, under results_mutex
  agent::TrainMetrics last_metrics;
  LearnerStats stats;
  std::function<void(const std::string&)> progress;
  service::MetricsInterval interval;  // since the last metrics line
  double interval_lag_sum = 0.0;
  std::uint64_t interval_chunks = 0;
};

Learner::Learner(const service::ServiceConfig& config) : impl_(std::make_unique<Impl>(config)) {}
Learner::~Learner() = default;
void Learner::on_progress(std::function<void(const std::string&)> callback) {
  impl_->progress = std::move(callback);
}
int Learner::run(const std::atomic<bool>& stop) {
  const int code = impl_->run_loop(stop);
  impl_->stats.dropped_chunks = impl_->chunks.drops().dropped();
  return code;
}
const LearnerStats& Learner::stats() const { return impl_->stats; }

}  // namespace indrive::learner
