#include "indrive/learner/learner.h"

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <deque>
#include <map>
#include <mutex>
#include <nlohmann/json.hpp>
#include <optional>
#include <sstream>
#include <thread>

#include "indrive/agent/agent.h"
#include "indrive/basics/check.h"
#include "indrive/basics/log.h"
#include "indrive/basics/run_dir.h"
#include "indrive/dds/participant.h"
#include "indrive/dds/security.h"
#include "indrive/learner/evaluation_tally.h"
#include "indrive/learner/ingest.h"
#include "indrive/learner/rate_limiter.h"
#include "indrive/nn/kernels.h"

namespace indrive::learner {
namespace fs = std::filesystem;
namespace {

using Clock = std::chrono::steady_clock;
// Versions are reserved in blocks written to this file before any of them is published, so a
// learner killed between checkpoints never hands out a version twice after its restart.
constexpr std::string_view kVersionReserveFile = "policy_versions_reserved";
constexpr std::uint64_t kVersionReserveBlock = 100;
// A damaged checkpoint that a resume skipped is renamed to <name> + this, out of the rotation:
// its counter sorts after the checkpoints the resumed learner writes next, so left in place it
// would stay "newest" and the retention of learner.checkpoint_keep would delete intact ones.
constexpr std::string_view kDamagedSuffix = ".damaged";

double seconds_since(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

double unix_time_s() {
  return std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
}

}  // namespace

struct Learner::Impl {
  explicit Impl(const service::ServiceConfig& service)
      : config(service),
        agent_config(service.agent()),
        run(RunDir::open_or_create(service.run_dir().parent_path().empty()
                                       ? fs::path(".")
                                       : service.run_dir().parent_path(),
                                   service.run_id())),
        checkpoints(run.checkpoints(), service.config().get<int>("learner.checkpoint_keep")),
        replay(replay_options(agent_config)),
        rate({.replay_ratio = service.config().get<double>("learner.replay_ratio"),
              .steps_per_update =
                  static_cast<std::int64_t>(agent_config.replay.batch) * agent_config.replay.length,
              .prefill = agent_config.replay.prefill,
              // At least one chunk, so an actor can always finish the chunk it holds.
              .slack = std::max(service.config().get<std::int64_t>("learner.allowance_slack"),
                                service.config().get<std::int64_t>("actor.chunk_length")),
              .async = service.config().get<bool>("learner.async")}),
        ingest({.run_id = service.run_id(),
                .height = agent_config.world_model.image,
                .width = agent_config.world_model.image,
                .phase = service.wire_phase(),
                .with_rewards = agent_config.phase != agent::Phase::kPretrain}),
        metrics(run.metrics_path()) {
    const auto& c = service.config();
    budget = c.get<std::int64_t>("run.budget_env_steps");
    snapshot_every = c.get<std::int64_t>("learner.snapshot_every");
    announce_s = c.get<double>("learner.announce_s");
    log_interval_s = c.get<double>("learner.log_interval_s");
    log_every_steps = c.get<std::int64_t>("learner.log_every_env_steps");
    checkpoint_s = c.get<double>("learner.checkpoint_minutes") * 60.0;
    config.config().write_yaml(run.config_path());

    resume();
    fill_target = std::min<std::int64_t>(agent_config.replay.prefill, agent_config.replay.capacity);
    // Actors may always run until replay holds the prefill again; a restored replay needs none.
    fill_floor = stats.counters.env_steps + std::max<std::int64_t>(0, fill_target - replay.size());

    participant = std::make_unique<dds::Participant>(service.participant_options("learner"));
    policy_writer = participant->make_writer<msg::PolicySnapshot>();
    announce_writer = participant->make_writer<msg::SnapshotAnnounce>();
    allowance_writer = participant->make_writer<msg::StepAllowance>();
    heartbeat_writer = participant->make_writer<msg::Heartbeat>();
    chunk_reader = participant->make_reader<msg::TrajectoryChunk>(
        [this](const msg::TrajectoryChunk& chunk) { on_chunk(chunk); });
    result_reader = participant->make_reader<msg::EpisodeResult>(
        [this](const msg::EpisodeResult& result) { on_result(result); });
    request_reader =
        participant->make_reader<msg::SnapshotRequest>([this](const msg::SnapshotRequest& request) {
          if (dds::validate(request, config.run_id()) != dds::DropReason::kOk) return;
          republish_requested.store(true);
        });
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

  ~Impl() {
    chunk_reader.reset();
    result_reader.reset();
    request_reader.reset();
    policy_writer.reset();
    announce_writer.reset();
    allowance_writer.reset();
    heartbeat_writer.reset();
    participant.reset();
  }

  static agent::ReplayOptions replay_options(const agent::AgentConfig& agent_config) {
    return {.capacity = agent_config.replay.capacity,
            .height = agent_config.world_model.image,
            .width = agent_config.world_model.image,
            .has_rewards = agent_config.phase != agent::Phase::kPretrain,
            .seed = agent_config.replay.seed + agent_config.seed};
  }

  // What one checkpoint file restores, loaded into fresh objects: a file that fails half way
  // (the agent loads its parameters before it checks its normalisers, for one) leaves nothing
  // of itself in the learner's own agent and replay.
  struct Restored {
    LearnerCounters counters;
    std::unique_ptr<agent::Agent> agent;
    std::optional<agent::ReplayBuffer> replay;
  };

  Restored restore(const fs::path& file) const {
    std::vector<std::uint8_t> agent_bytes, replay_bytes;
    Restored restored;
    restored.counters = unpack_checkpoint(read_file(file), agent_bytes, &replay_bytes);
    restored.agent = std::make_unique<agent::Agent>(agent_config);
    restored.agent->load_checkpoint(agent_bytes, file.string() + " (agent section)");
    restored.replay.emplace(replay_options(agent_config));
    if (!replay_bytes.empty()) restored.replay->load(replay_bytes, file.string() + " (replay)");
    return restored;
  }

  // Restores the newest intact checkpoint of this run, or a finetune's initial checkpoint.
  void resume() {
    const std::vector<fs::path> files = checkpoints.list();
    if (!files.empty()) {
      resume_from(files);
    } else if (const auto init = config.config().get<std::string>("learner.init_checkpoint");
               !init.empty()) {
      const auto bytes = read_file(init);
      std::vector<std::uint8_t> agent_bytes;
      try {
        unpack_checkpoint(bytes, agent_bytes);
      } catch (const CheckpointError&) {
        agent_bytes = bytes;  // a bare agent checkpoint
      }
      agent = std::make_unique<agent::Agent>(agent_config);
      agent->load_checkpoint(agent_bytes, init);
      INDRIVE_LOG(kInfo, "learner") << "initialised from " << init;
    } else {
      agent = std::make_unique<agent::Agent>(agent_config);
    }
    ++stats.counters.learner_epoch;
    // Snapshots published after the newest checkpoint used versions up to the reserved mark.
    reserved_version = read_reserved_version();
    stats.counters.policy_version = std::max(stats.counters.policy_version, reserved_version);
  }

  // Tries the checkpoints (oldest first in `files`) newest first and keeps the first that
  // restores completely. A damaged file is skipped with a warning, not fatal: a checkpoint cut
  // short by a crash of the machine or a bit flip on disk should cost the run only the updates
  // since the older one. With none intact the learner refuses to start rather than start the
  // run again from nothing, which would silently throw away the run's training so far.
  void resume_from(const std::vector<fs::path>& files) {
    std::vector<std::pair<fs::path, std::string>> damaged;
    for (auto file = files.rbegin(); file != files.rend(); ++file) {
      Restored restored;
      try {
        restored = restore(*file);
      } catch (const std::exception& error) {
        // Whatever the loaders throw: CheckpointError, agent::AgentError, agent::ReplayError,
        // IoError when the file cannot be read, std::bad_alloc for sizes no memory holds.
        damaged.emplace_back(*file, error.what());
        INDRIVE_LOG(kWarn, "learner") << "checkpoint " << file->string()
                                      << " cannot be restored and is skipped: " << error.what();
        continue;
      }
      stats.counters = restored.counters;
      agent = std::move(restored.agent);
      replay = std::move(*restored.replay);
      stats.restored_replay_steps = replay.size();
      stats.resumed_from = *file;
      stats.skipped_checkpoints = damaged.size();
      latest_checkpoint = *file;
      for (const auto& [path, reason] : damaged) set_aside(path);
      INDRIVE_LOG(kInfo, "learner")
          << "resumed from " << file->string() << " with " << replay.size()
          << " replay steps (skipped " << damaged.size() << " damaged newer checkpoint"
          << (damaged.size() == 1 ? "" : "s") << ")";
      return;
    }
    std::string message = "no checkpoint of run '" + config.run_id() + "' can be restored (" +
                          std::to_string(damaged.size()) + " tried):";
    for (const auto& [path, reason] : damaged) message += "\n  " + path.string() + ": " + reason;
    message +=
        "\nThe learner does not start the run again from nothing on its own: restore an "
        "intact copy, or move these files out of " +
        run.checkpoints().string() + " to start the run afresh.";
    throw CheckpointError(message);
  }

  // Moves a damaged checkpoint out of the rotation, keeping its bytes for a look.
  void set_aside(const fs::path& file) {
    const fs::path target = file.string() + std::string(kDamagedSuffix);
    std::error_code error;
    fs::rename(file, target, error);
    if (error) {
      INDRIVE_LOG(kWarn, "learner")
          << "could not rename damaged checkpoint " << file.string() << " to "
          << target.filename().string() << ": " << error.message() << "; move it away by hand";
    } else {
      INDRIVE_LOG(kWarn, "learner")
          << "damaged checkpoint " << file.string() << " set aside as "
          << target.filename().string() << "; delete it once it is no longer needed";
    }
  }

  std::uint64_t read_reserved_version() const {
    const fs::path path = run.checkpoints() / kVersionReserveFile;
    if (!fs::exists(path)) return 0;
    const auto bytes = read_file(path);
    try {
      return std::stoull(std::string(bytes.begin(), bytes.end()));
    } catch (const std::exception&) {
      throw CheckpointError("file " + path.string() +
                            " does not hold a policy version; delete it only if no actor of this "
                            "run still holds a snapshot");
    }
  }

  // Makes sure `version` is reserved on disk before it is published.
  void reserve_version(std::uint64_t version) {
    if (version <= reserved_version) return;
    reserved_version = version + kVersionReserveBlock - 1;
    atomic_write(run.checkpoints() / kVersionReserveFile, std::to_string(reserved_version));
  }

  // After the final checkpoint no version above the current one was published: a clean
  // restart continues right after it instead of after the reserved block.
  // Failing to write it (disk full) is harmless: the larger reservation on disk stays valid.
  void release_reserved_versions() {
    if (reserved_version <= stats.counters.policy_version) return;
    try {
      atomic_write(run.checkpoints() / kVersionReserveFile,
                   std::to_string(stats.counters.policy_version));
      reserved_version = stats.counters.policy_version;
    } catch (const IoError& error) {
      INDRIVE_LOG(kWarn, "learner") << "reserved policy versions not released: " << error.what()
                                    << "; a restart skips to v" << reserved_version + 1;
    }
  }

  // Writes a checkpoint; returns whether it was written. A write that fails (disk full, I/O
  // error) is logged and counted but does not end the run: atomic_write leaves the previous
  // checkpoint as it was and no partial file, and the next checkpoint time tries again.
  // `final`: the one at exit, which has no next try.
  bool save_checkpoint(bool final = false) {
    const auto start = Clock::now();
    // Replay goes into the same file, so counters, model and data always match.
    const auto agent_bytes = agent->checkpoint_bytes();
    const auto replay_bytes = replay.to_bytes();
    const auto packed = pack_checkpoint(stats.counters, agent_bytes, replay_bytes);
    const auto counter = static_cast<std::uint64_t>(stats.counters.updates);
    fs::path path;
    try {
      path = checkpoints.save(counter, packed);
    } catch (const IoError& error) {
      last_checkpoint = Clock::now();
      ++stats.checkpoint_failures;
      std::ostringstream next;
      if (!final) next << "; the next try is in " << checkpoint_s << " s (free space on that disk)";
      INDRIVE_LOG(kError, "learner")
          << (final ? "final " : "") << "checkpoint "
          << checkpoints.path(counter).filename().string() << " (" << packed.size()
          << " bytes) was not written: " << error.what() << "; "
          << (latest_checkpoint.empty()
                  ? "this run has no earlier checkpoint"
                  : "the previous checkpoint " + latest_checkpoint.string() + " is intact")
          << "; " << stats.checkpoint_failures << " failed in this run" << next.str();
      return false;
    }
    last_checkpoint = Clock::now();
    latest_checkpoint = path;
    ++stats.checkpoints;
    INDRIVE_LOG(kInfo, "learner") << "checkpoint " << path.filename().string() << " ("
                                  << packed.size() << " bytes: agent " << agent_bytes.size()
                                  << ", replay of " << replay.size() << " steps "
                                  << replay_bytes.size() << " -> "
                                  << packed.size() - agent_bytes.size() << " compressed; "
                                  << seconds_since(start) << " s)";
    return true;
  }

  // DDS thread: decode and queue; the acting thread owns the replay buffer.
  void on_chunk(const msg::TrajectoryChunk& chunk) {
    DecodedChunk decoded;
    dds::DropReason reason = decode_chunk(chunk, ingest, decoded);
    if (reason == dds::DropReason::kOk && !stored_chunks.first_time(chunk)) {
      reason = dds::DropReason::kDuplicate;
    }
    drops.record(reason);
    if (reason != dds::DropReason::kOk) {
      INDRIVE_LOG(kWarn, "learner")
          << "dropped chunk " << chunk.chunk_seq() << " of actor " << chunk.actor_id() << " (run '"
          << chunk.run_id() << "'): " << dds::drop_reason_name(reason);
      return;
    }
    std::lock_guard<std::mutex> lock(queue_mutex);
    queue.push_back(std::move(decoded));
  }

  void on_result(const msg::EpisodeResult& result) {
    if (dds::validate(result, config.run_id()) != dds::DropReason::kOk) return;
    if (result.sender_role() == msg::ROLE_EVALUATOR) {
      evaluations.add(result);
      return;
    }
    if (result.sender_role() != msg::ROLE_ACTOR) return;
    std::lock_guard<std::mutex> lock(queue_mutex);
    ++interval_episodes;
    interval_successes += result.success() ? 1 : 0;
    episode_stats.add(result.steps(), result.reach_segments());
  }

  // Moves queued chunks into replay; returns whether there were any.
  bool drain() {
    std::deque<DecodedChunk> taken;
    {
      std::lock_guard<std::mutex> lock(queue_mutex);
      taken.swap(queue);
    }
    for (DecodedChunk& chunk : taken) {
      // A missing predecessor (lost chunk) must not glue two pieces of trajectory together.
      // After a learner restart the first chunk of an actor follows steps that were never
      // stored (they arrived after the checkpoint), so it starts a new piece as well.
      auto expected = next_seq.find(chunk.actor_id);
      if (chunk.chunk_seq != 0 &&
          (expected == next_seq.end() || expected->second != chunk.chunk_seq)) {
        ++stats.sequence_gaps;
        chunk.steps.front().is_first = true;
      }
      next_seq[chunk.actor_id] = chunk.chunk_seq + 1;
      for (const auto& step : chunk.steps) replay.add(static_cast<int>(chunk.actor_id), step);
      stats.counters.env_steps += static_cast<std::int64_t>(chunk.steps.size());
      ++stats.chunks;
      interval_lag_sum += static_cast<double>(stats.counters.policy_version - chunk.policy_version);
      ++interval_chunks;
    }
    return !taken.empty();
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
    if (stats.counters.updates % snapshot_every == 0) publish_snapshot();
  }

  void publish_snapshot() {
    msg::PolicySnapshot snapshot;
    snapshot.run_id(config.run_id());
    reserve_version(stats.counters.policy_version + 1);
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
    dds::seal(snapshot);
    policy_writer->write(snapshot);
    newest_snapshot = std::move(snapshot);
    ++stats.snapshots_published;
    publish_announce();
  }

  void publish_announce() {
    if (!newest_snapshot) return;
    msg::SnapshotAnnounce announce;
    announce.run_id(config.run_id());
    announce.version(newest_snapshot->version());
    announce.checksum(newest_snapshot->checksum());
    announce.size_bytes(newest_snapshot->params().size());
    announce.learner_done(done);
    dds::seal(announce);
    announce_writer->write(announce);
    last_announce = Clock::now();
  }

  // Tells evaluators reliably which snapshot is the run's last: the heartbeat's "done" is best
  // effort and can be lost as the process exits, which left an evaluator waiting for it. The
  // announce is reliable and the learner waits (bounded) until every matched reader has it.
  void announce_final_snapshot() {
    if (!newest_snapshot) return;
    publish_announce();
    if (!announce_writer->wait_for_acknowledgments(std::chrono::seconds(5))) {
      INDRIVE_LOG(kWarn, "learner") << "not every reader acknowledged the final announce of v"
                                    << newest_snapshot->version() << " within 5 s";
    }
  }

  std::uint64_t allowance() const {
    std::uint64_t allowed = rate.allowance(stats.counters.updates, fill_floor);
    if (budget > 0) allowed = std::min<std::uint64_t>(allowed, static_cast<std::uint64_t>(budget));
    return allowed;
  }

  // Publishes the allowance when it changed and the learner's heartbeat (which tells actors
  // how many steps arrived) at least every 100 ms.
  void publish_pacing(bool force) {
    const std::uint64_t allowed = allowance();
    const bool changed =
        allowed != published_allowance || stats.counters.env_steps != published_received;
    if (!force && !(changed && seconds_since(last_pacing) > 0.005) &&
        seconds_since(last_pacing) < 0.1) {
      return;
    }
    msg::StepAllowance message;
    message.run_id(config.run_id());
    message.total_env_steps(allowed);
    message.replay_ratio(rate.options().replay_ratio);
    message.learner_epoch(stats.counters.learner_epoch);
    message.policy_version(stats.counters.policy_version);
    dds::seal(message);
    allowance_writer->write(message);

    msg::Heartbeat beat;
    beat.role(msg::ROLE_LEARNER);
    beat.id(0);
    beat.run_id(config.run_id());
    beat.state(done ? "done" : "running");
    beat.policy_version(stats.counters.policy_version);
    beat.env_steps(static_cast<std::uint64_t>(stats.counters.env_steps));
    beat.updates(static_cast<std::uint64_t>(stats.counters.updates));
    beat.dropped_messages(drops.dropped());
    beat.wall_time_s(unix_time_s());
    dds::seal(beat);
    heartbeat_writer->write(beat);
    published_allowance = allowed;
    published_received = stats.counters.env_steps;
    last_pacing = Clock::now();
  }

  void log_metrics() {
    const double elapsed = seconds_since(last_log);
    if (elapsed < log_interval_s &&
        !passed_multiple(logged_steps, stats.counters.env_steps, log_every_steps)) {
      return;
    }
    const std::int64_t steps = stats.counters.env_steps - logged_steps;
    const std::int64_t updates = stats.counters.updates - logged_updates;
    const double ratio = stats.counters.env_steps > 0
                             ? static_cast<double>(stats.counters.updates) *
                                   rate.options().steps_per_update /
                                   static_cast<double>(stats.counters.env_steps)
                             : 0.0;
    std::uint64_t episodes = 0, successes = 0;
    auto episode_record = nlohmann::json::object();  // length and reach of the actors' episodes
    {
      std::lock_guard<std::mutex> lock(queue_mutex);
      std::swap(episodes, interval_episodes);
      std::swap(successes, interval_successes);
      episode_stats.write(episode_record);
    }
    stats.episodes += episodes;
    const double lag = interval_chunks > 0 ? interval_lag_sum / interval_chunks : 0.0;
    nlohmann::json record = {{"env_steps", stats.counters.env_steps},
                             {"updates", stats.counters.updates},
                             {"learner_epoch", stats.counters.learner_epoch},
                             {"env_steps_per_s", steps / std::max(elapsed, 1e-9)},
                             {"updates_per_s", updates / std::max(elapsed, 1e-9)},
                             {"replay_ratio", ratio},
                             {"policy_version", stats.counters.policy_version},
                             {"policy_lag", lag},
                             {"replay_size", replay.size()},
                             {"replay_added", replay.total_added()},
                             {"snapshots_published", stats.snapshots_published},
                             {"snapshot_requests", stats.snapshot_requests},
                             {"chunks", stats.chunks},
                             {"replay_actors", next_seq.size()},
                             {"dropped_chunks", drops.dropped()},
                             {"dropped_wrong_run", drops.count(dds::DropReason::kWrongRun)},
                             {"dropped_bad_checksum", drops.count(dds::DropReason::kBadChecksum)},
                             {"dropped_bad_shape", drops.count(dds::DropReason::kBadShape)},
                             {"dropped_wrong_schema", drops.count(dds::DropReason::kWrongSchema)},
                             {"dropped_duplicate", drops.count(dds::DropReason::kDuplicate)},
                             {"dropped_undecodable", dds::undecodable_samples()},
                             {"sequence_gaps", stats.sequence_gaps},
                             {"failed_updates", stats.failed_updates},
                             {"checkpoints", stats.checkpoints},
                             {"checkpoint_failures", stats.checkpoint_failures},
                             {"episodes", episodes},
                             {"phase", std::string(agent::to_string(agent_config.phase))}};
    if (episodes > 0) record["episode_success_rate"] = static_cast<double>(successes) / episodes;
    record.update(episode_record);
    evaluations.write_new(record);
    for (const auto& [name, value] : last_metrics) record[name] = value;
    metrics.write(record);

    std::ostringstream line;
    line.precision(3);
    line << "steps " << stats.counters.env_steps << " | updates " << stats.counters.updates << " | "
         << steps / elapsed << " steps/s | " << updates / elapsed << " upd/s | ratio " << ratio
         << " | policy v" << stats.counters.policy_version << " lag " << lag << " | dropped "
         << drops.dropped();
    int shown = 0;
    for (const auto& [name, value] : last_metrics) {
      if (name.find("loss") == std::string::npos || shown++ >= 4) continue;
      line << " | " << name << " " << value;
    }
    if (progress) progress(line.str());
    last_log = Clock::now();
    logged_steps = stats.counters.env_steps;
    logged_updates = stats.counters.updates;
    interval_lag_sum = 0.0;
    interval_chunks = 0;
  }

  int run_loop(const std::atomic<bool>& stop) {
    last_checkpoint = last_log = Clock::now();
    logged_steps = stats.counters.env_steps;
    logged_updates = stats.counters.updates;
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
      if (republish_requested.exchange(false) && newest_snapshot) {
        ++stats.snapshot_requests;
        policy_writer->write(*newest_snapshot);
        publish_announce();
      }
      if (seconds_since(last_announce) >= announce_s) publish_announce();
      log_metrics();
      if (seconds_since(last_checkpoint) >= checkpoint_s) save_checkpoint();
      // The budget ends the run once the updates it is owed are done.
      if (budget > 0 && stats.counters.env_steps >= budget &&
          (rate.options().async || !ready_to_train())) {
        done = true;
        break;
      }
      if (!worked) std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    // Chunks already received are stored, so the final checkpoint keeps them.
    drain();
    // At the budget's end a run that never published a snapshot (snapshot_every above its
    // updates) publishes its parameters, so evaluators of a short run have a policy. Only then:
    // a snapshot written just before the learner exits can be lost to readers still fetching
    // it, and the newest periodic snapshot is the run's final policy otherwise. The learner
    // lingers briefly so readers can fetch it.
    if (done && stats.counters.updates > 0 && !newest_snapshot) {
      publish_snapshot();
      INDRIVE_LOG(kInfo, "learner") << "final snapshot v" << stats.counters.policy_version << " at "
                                    << stats.counters.updates << " updates";
      std::this_thread::sleep_for(std::chrono::seconds(2));
    }
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
          << (latest_checkpoint.empty() ? "nothing (this run has no checkpoint)"
                                        : latest_checkpoint.string())
          << " and what was trained and received after it is lost; free disk space before the "
             "run continues";
    }
    release_reserved_versions();
    last_log = Clock::now() - std::chrono::hours(1);
    log_metrics();
    publish_pacing(true);
    if (done) announce_final_snapshot();
    INDRIVE_LOG(kInfo, "learner") << (done ? "budget reached" : "stopped") << ": "
                                  << stats.counters.env_steps << " env steps, "
                                  << stats.counters.updates << " updates, policy v"
                                  << stats.counters.policy_version << ", chunks " << stats.chunks
                                  << ", " << drops.summary() << ", checkpoints "
                                  << stats.checkpoints << " (" << stats.checkpoint_failures
                                  << " failed)";
    return code;
  }

  const service::ServiceConfig& config;
  agent::AgentConfig agent_config;
  RunDir run;
  CheckpointFiles checkpoints;
  std::unique_ptr<agent::Agent> agent;  // set by resume()
  agent::ReplayBuffer replay;
  RateLimiter rate;
  IngestOptions ingest;
  MetricsLog metrics;
  EvaluationTally evaluations;  // evaluators' results, on the metrics lines
  std::int64_t budget = 0;
  std::int64_t snapshot_every = 10;
  double announce_s = 1.0;
  double log_interval_s = 5.0;
  std::int64_t log_every_steps = 1000;
  double checkpoint_s = 300.0;
  std::int64_t fill_target = 0;
  std::int64_t fill_floor = 0;
  std::uint64_t reserved_version = 0;
  fs::path latest_checkpoint;  // the newest intact checkpoint this learner wrote or resumed from
  bool done = false;

  std::unique_ptr<dds::Participant> participant;
  std::unique_ptr<dds::Writer<msg::PolicySnapshot>> policy_writer;
  std::unique_ptr<dds::Writer<msg::SnapshotAnnounce>> announce_writer;
  std::unique_ptr<dds::Writer<msg::StepAllowance>> allowance_writer;
  std::unique_ptr<dds::Writer<msg::Heartbeat>> heartbeat_writer;
  std::unique_ptr<dds::Reader<msg::TrajectoryChunk>> chunk_reader;
  std::unique_ptr<dds::Reader<msg::EpisodeResult>> result_reader;
  std::unique_ptr<dds::Reader<msg::SnapshotRequest>> request_reader;

  dds::DropCounters drops;
  DuplicateFilter stored_chunks;  // chunks stored so far: a repeat is dropped
  std::mutex queue_mutex;
  std::deque<DecodedChunk> queue;
  std::uint64_t interval_episodes = 0, interval_successes = 0;
  EpisodeStats episode_stats;  // under queue_mutex
  std::map<std::uint32_t, std::uint64_t> next_seq;
  std::atomic<bool> republish_requested{false};
  std::optional<msg::PolicySnapshot> newest_snapshot;
  agent::TrainMetrics last_metrics;
  LearnerStats stats;
  std::function<void(const std::string&)> progress;
  std::uint64_t published_allowance = 0;
  std::int64_t published_received = -1;
  Clock::time_point last_pacing{}, last_announce{}, last_log{}, last_checkpoint{};
  std::int64_t logged_steps = 0, logged_updates = 0;
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
  impl_->stats.dropped_chunks = impl_->drops.dropped();
  return code;
}
const LearnerStats& Learner::stats() const { return impl_->stats; }

}  // namespace indrive::learner
