#include "indrive/actor/evaluator.h"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <map>
#include <optional>
#include <set>
#include <sstream>
#include <stdexcept>
#include <thread>
#include <tuple>

#include "indrive/actor/actor_config.h"
#include "indrive/actor/env_adapter.h"
#include "indrive/actor/eval_protocol_episode.h"
#include "indrive/actor/eval_protocol_record.h"
#include "indrive/actor/learner_link.h"
#include "indrive/actor/policies.h"
#include "indrive/actor/snapshot_file.h"
#include "indrive/agent/snapshot_file.h"
#include "indrive/basics/check.h"
#include "indrive/basics/episode_csv.h"
#include "indrive/basics/log.h"
#include "indrive/basics/run_dir.h"
#include "indrive/dds/participant.h"
#include "indrive/dds/security.h"
#include "text.h"

namespace indrive::actor {
namespace {

using Clock = std::chrono::steady_clock;

// What one finished episode gives.
// Appends learning-curve rows, writing the header first when the file is new.
class CurveWriter {
 public:
  explicit CurveWriter(const std::filesystem::path& path) {
    const bool fresh = !std::filesystem::exists(path) || std::filesystem::file_size(path) == 0;
    out_.open(path, std::ios::app);
    if (!out_) throw EvalError("cannot append to learning curve " + path.string());
    if (fresh) out_ << curve_csv_header() << '\n' << std::flush;
  }
  void write(std::uint64_t env_steps, const EpisodeRecord& r) {
    out_ << env_steps << ',' << r.policy_version << ',' << r.method << ',' << r.eval_kind << ','
         << r.task << ',' << r.town << ',' << r.route << ',' << r.density << ',' << r.traffic_seed
         << ',' << r.spawn_seed << ',' << r.episode << ',' << (r.success ? 1 : 0) << ','
         << r.failure_reason << ',' << r.steps << ',' << r.route_completion << ','
         << r.episode_return << '\n'
         << std::flush;
  }

 private:
  std::ofstream out_;
};

}  // namespace

const std::string& curve_csv_header() {
  static const std::string header =
      "env_steps,policy_version,method,eval_kind,task,town,route,density,traffic_seed,spawn_seed,"
      "episode,success,failure_reason,steps,route_completion,episode_return";
  return header;
}

ProtocolGrid protocol_grid(const config::Config& config) {
  const EvalConfig eval = eval_config(config);
  ProtocolGrid grid;
  grid.towns = split_list(eval.towns);
  set_grid_routes(grid, eval.routes, town_options(config));
  grid.densities.clear();
  for (double density : eval.densities) grid.densities.push_back(static_cast<int>(density));
  grid.episodes_per_cell = eval.episodes_per_cell;
  grid.validate();
  check_grid_names(grid);
  return grid;
}

struct Evaluator::Impl {
  Impl(const service::ServiceConfig& service, int evaluator_index, int evaluator_count)
      : config(service),
        eval(eval_config(service.config())),
        actor_settings(actor_config(service.config())),
        index(evaluator_index),
        count(evaluator_count),
        agent_config(service.agent()),
        grid(protocol_grid(service.config())) {
    // Inputs first, so a mistake is reported before SUMO or DDS start.
    source = parse_policy_source(eval.policy);
    head = resolve_head(eval.head, eval.kind);
    snapshot_file = eval.snapshot_file;
    continuous = eval.continuous;
    if (!snapshot_file.empty() && source != PolicySource::kSnapshot) {
      throw EvalError("eval.snapshot_file (--snapshot) is given but eval.policy is '" +
                      std::string(to_string(source)) + "'; use --policy snapshot");
    }
    if (continuous && eval.resume) {
      throw EvalError(
          "eval.resume goes on with one evaluation stopped part-way; a --continuous learning "
          "curve is not resumed: leave eval.resume off");
    }
    if (continuous && (source != PolicySource::kSnapshot || !snapshot_file.empty())) {
      throw EvalError(
          "--continuous follows a learner's snapshots over DDS; it cannot be combined with "
          "--snapshot FILE or with the oracle or random policy");
    }
    (void)grid.episodes_for(index, count);  // throws for an index outside the count
    switch (source) {
      case PolicySource::kOracle:
        method = eval.oracle_brake ? "oracle" : "oracle_nobrake";
        policy = make_oracle_policy(
            {.target_speed_mps = eval.oracle_speed_mps, .brake_for_leader = eval.oracle_brake});
        break;
      case PolicySource::kRandom:
        method = "random";
        policy = make_random_policy(agent_config.seed);
        break;
      case PolicySource::kSnapshot:
        if (!snapshot_file.empty()) {
          // The file's header sizes the model (and the camera) unless the config chose sizes.
          snapshot_file = snapshot_file_path(snapshot_file);  // a run directory: its final one
          agent::SnapshotFile file;
          try {
            file = agent::read_snapshot_file(snapshot_file);
          } catch (const agent::SnapshotFileError& error) {
            throw EvalError(error.what());
          }
          const std::string name = "snapshot file " + snapshot_file.string();
          const std::string note =
              adopt_snapshot_architecture(agent_config, file, service.agent_choices(), name);
          if (!note.empty()) {
            INDRIVE_LOG(kInfo, "evaluator") << note;
          }
          policy = make_snapshot_policy(agent_config, file.blob, head, name);
        }
        method = agent::method_label(agent_config);
        break;
    }
    task = head == PolicyHead::kExploration ? "exploration" : agent_config.task;

    if (source == PolicySource::kSnapshot && snapshot_file.empty()) {
      // A participant that has heard the learner is never replaced: the evaluator's answer to a
      // silent learner is eval.learner_silence_s (learner_link.h says why participants are).
      link = std::make_unique<LearnerLink>(
          service,
          LearnerLinkOptions{.role = "evaluator",
                             .requester_role = msg::ROLE_EVALUATOR,
                             .id = static_cast<std::uint32_t>(index),
                             .architecture = service::architecture_descriptor(agent_config),
                             .request_after_s = actor_settings.request_after_s,
                             .rejoin_after_s = actor_settings.rejoin_after_s,
                             .rejoin_max_s = actor_settings.rejoin_max_s,
                             .replace_silent_over_shm = false});
    }
    env::EnvConfig env_config = protocol_env_config(actor::env_config(service, agent_config),
                                                    parse_protocol(eval.protocol));
    env_config.town = grid.towns.front();
    env = std::make_unique<env::Env>(env_config);
  }

  // The version the learner declared its last, by its reliable final announce or its
  // heartbeat (0: not yet).
  std::uint64_t final_version() const { return link ? link->final_version() : 0; }

  // True when the learner has not been heard from for eval.learner_silence_s since `since` (the
  // later of the two counts): it died, or it ended without its final announce reaching us.
  bool learner_silent(Clock::time_point since) const {
    const double limit_s = eval.learner_silence_s;
    if (limit_s <= 0.0) return false;
    const Clock::time_point beat = link->heard_at();
    return std::chrono::duration<double>(Clock::now() - std::max(since, beat)).count() > limit_s;
  }

  // Says that the learner fell silent and what the evaluator does about it.
  void warn_silent_learner(const std::string& consequence) const {
    INDRIVE_LOG(kWarn, "evaluator")
        << "the learner of run '" << config.run_id() << "' has been silent for more than "
        << eval.learner_silence_s << " s without announcing its final snapshot; " << consequence
        << " (eval.learner_silence_s sets the wait, 0 waits for the learner)";
  }
  void warn_evaluating_unannounced(std::uint64_t version) const {
    warn_silent_learner("evaluating snapshot v" + std::to_string(version) +
                        ", the newest received, which may not be the run's last "
                        "(policy_version in the results says which)");
  }

  // The learner's final snapshot from <run>/final-snapshot.params (the learner writes it when
  // its run ends, learner.cc), when this evaluator shares the learner's run directory and the
  // file is of this run, newer than `after` and of this evaluator's architecture; else nullptr.
  // It is how an evaluator that received no final snapshot over DDS still evaluates the run's
  // end: one restarted after the learner exited, or one its learner's samples never reached
  // (a participant left deaf by a killed process's shared-memory port, docs/operations.md).
  // Also nullptr when the file's version is under `at_least` (the final version
  // announced, or a snapshot already held).
  std::shared_ptr<const msg::PolicySnapshot> final_snapshot_from_file(std::uint64_t after,
                                                                      std::uint64_t at_least) {
    const std::filesystem::path path = final_snapshot_path(config.run_dir());
    std::error_code error;
    if (!std::filesystem::is_regular_file(path, error)) return nullptr;
    const auto mtime = std::filesystem::last_write_time(path, error);
    if (error || mtime == final_file_seen) return nullptr;  // read (and refused) already
    final_file_seen = mtime;
    agent::SnapshotFile file;
    try {
      file = agent::read_snapshot_file(path);
    } catch (const agent::SnapshotFileError& bad) {
      INDRIVE_LOG(kWarn, "evaluator") << "not using the learner's final snapshot: " << bad.what();
      return nullptr;
    }
    const auto provenance = file.provenance();
    std::string refused;
    if (!provenance || provenance->run_id != config.run_id()) {
      refused = "it is not of run '" + config.run_id() + "'";
    } else if (provenance->version <= after || provenance->version < at_least) {
      return nullptr;
    } else {
      for (const std::string& key : agent::snapshot_architecture_keys()) {
        if (!agent::is_snapshot_size_key(key) && key != "phase") continue;
        const std::string have = agent::snapshot_key_text(agent_config, key);
        if (file.value(key) != have) {
          refused = "its " + key + " is " + file.value(key) + " where this evaluator has " + have;
          break;
        }
      }
    }
    if (!refused.empty()) {
      INDRIVE_LOG(kWarn, "evaluator")
          << "not using " << path.string() << " as the final snapshot: " << refused;
      return nullptr;
    }
    auto snapshot = std::make_shared<msg::PolicySnapshot>();
    snapshot->run_id(provenance->run_id);
    snapshot->version(provenance->version);
    snapshot->env_steps(provenance->env_steps);
    snapshot->params(std::move(file.blob));
    INDRIVE_LOG(kInfo, "evaluator")
        << "evaluator " << index << " takes the learner's final snapshot v" << provenance->version
        << " from " << path.string() << " (none arrived over DDS)";
    return snapshot;
  }

  // The snapshot to evaluate: newer than `after`, and the learner's final one when asked to
  // wait for it (or the newest held once the learner has gone silent; or, with none held or
  // announced as final, the learner's final snapshot file). nullptr when stopped or timed out.
  std::shared_ptr<const msg::PolicySnapshot> wait_for_snapshot(const std::atomic<bool>& stop,
                                                               std::uint64_t after,
                                                               bool wait_for_done,
                                                               double timeout_s) {
    const auto start = Clock::now();
    while (!stop.load() &&
           std::chrono::duration<double>(Clock::now() - start).count() < timeout_s) {
      auto snapshot = link->inbox().take_newer_than(after);
      const std::uint64_t last = final_version();
      if (snapshot != nullptr && (!wait_for_done || (last > 0 && snapshot->version() >= last))) {
        return snapshot;
      }
      if (wait_for_done && (last > 0 || learner_silent(start))) {
        auto from_file =
            final_snapshot_from_file(after, std::max(last, snapshot ? snapshot->version() : 0));
        if (from_file != nullptr) return from_file;
      }
      if (snapshot != nullptr && learner_silent(start)) {
        warn_evaluating_unannounced(snapshot->version());
        return snapshot;
      }
      if (link->inbox().should_request(snapshot ? snapshot->version() : after, Clock::now())) {
        link->request_snapshot();
      }
      link->maybe_rejoin();
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    return nullptr;
  }

  // Turns a learner's snapshot into the policy, checking it has the head to evaluate.
  void load(const msg::PolicySnapshot& snapshot) {
    policy = make_snapshot_policy(
        agent_config, snapshot.params(), head,
        "snapshot v" + std::to_string(snapshot.version()) + " of run " + config.run_id());
  }

  // An episode's place in the grid: town, route, density and index within the cell.
  using EpisodeKey = std::tuple<std::string, std::string, int, int>;

  // With eval.resume, the episodes the results file already holds for this evaluation (an
  // evaluation stopped or killed part-way goes on where it stopped). Every row must be of
  // this evaluation (run, method, kind, task, seed, policy version, protocol) and one of this
  // evaluator's episodes with the same seeds; anything else is an EvalError, since the file
  // would then mix two evaluations.
  std::set<EpisodeKey> finished_episodes(std::uint64_t version) const {
    std::set<EpisodeKey> finished;
    if (!eval.resume || !std::filesystem::exists(results_file())) return finished;
    std::map<EpisodeKey, EpisodeSpec> mine;
    for (const EpisodeSpec& spec : grid.episodes_for(index, count)) {
      mine[{spec.town, spec.route, spec.density, spec.episode}] = spec;
    }
    const std::string file = results_file().string();
    const auto fail = [&](std::size_t row, const std::string& what) {
      throw EvalError("eval.resume: row " + std::to_string(row + 1) + " of " + file + " " + what +
                      "; resume only into the results of the same evaluation, or evaluate " +
                      "into another run directory");
    };
    const std::vector<EpisodeRecord> rows = read_episode_csv(results_file());
    for (std::size_t i = 0; i < rows.size(); ++i) {
      const EpisodeRecord& r = rows[i];
      const auto differs = [&](const char* field, const std::string& theirs,
                               const std::string& ours) {
        if (theirs != ours) {
          fail(i, std::string("is of another evaluation (") + field + " '" + theirs +
                      "', this one '" + ours + "')");
        }
      };
      differs("run_id", r.run_id, config.run_id());
      differs("method", r.method, method);
      differs("eval_kind", r.eval_kind, eval.kind);
      differs("task", r.task, task);
      differs("train_seed", std::to_string(r.train_seed), std::to_string(agent_config.seed));
      differs("policy_version", std::to_string(r.policy_version), std::to_string(version));
      differs("protocol", r.protocol, eval.protocol);
      const EpisodeKey key{r.town, r.route, r.density, r.episode};
      const auto spec = mine.find(key);
      if (spec == mine.end()) {
        fail(i, "(" + r.town + " " + r.route + " density " + std::to_string(r.density) +
                    " episode " + std::to_string(r.episode) +
                    ") is not an episode of this evaluator's share of the grid");
      }
      if (spec->second.traffic_seed != r.traffic_seed || spec->second.spawn_seed != r.spawn_seed) {
        fail(i, "has other seeds than the grid gives its episode (run.seed changed?)");
      }
      finished.insert(key);
    }
    return finished;
  }

  // Runs this evaluator's episodes with the current policy, less those in `skip`; returns how
  // many finished.
  int run_episodes(const std::atomic<bool>& stop, std::uint64_t version, std::uint64_t env_steps,
                   EpisodeCsvWriter* csv, CurveWriter* curve,
                   const std::set<EpisodeKey>& skip = {}) {
    const auto episodes = grid.episodes_for(index, count);
    if (!skip.empty()) {
      INDRIVE_LOG(kInfo, "evaluator")
          << "evaluator " << index << " resumes: " << skip.size() << " of " << episodes.size()
          << " episodes are in " << results_file().string() << " already";
    }
    int done = 0;
    for (const EpisodeSpec& spec : episodes) {
      if (stop.load()) break;
      if (skip.contains({spec.town, spec.route, spec.density, spec.episode})) continue;
      const EpisodeOutcome outcome = run_protocol_episode(
          *env, *policy, spec,
          protocol_episode_options(config.config(), config.run_dir() / "videos"), stop);
      if (outcome.stopped) break;
      EpisodeRecord record = protocol_record(spec, outcome);
      record.run_id = config.run_id();
      record.method = method;
      record.eval_kind = eval.kind;
      record.task = task;
      record.train_seed = static_cast<int>(agent_config.seed);
      record.policy_version = static_cast<long long>(version);
      if (csv != nullptr) csv->write(record);
      if (curve != nullptr) curve->write(env_steps, record);
      publish(record, version);
      ++done;
    }
    INDRIVE_LOG(kInfo, "evaluator")
        << "evaluator " << index << " (" << method << ") ran " << done << " of "
        << episodes.size() - skip.size() << " episodes" << (skip.empty() ? "" : " left");
    return done;
  }

  void publish(const EpisodeRecord& record, std::uint64_t version) {
    if (!link) return;
    msg::EpisodeResult result;
    dds::set_episode_fields(result, record);
    result.run_id(config.run_id());
    result.policy_version(version);
    result.sender_role(msg::ROLE_EVALUATOR);
    result.sender_id(static_cast<std::uint32_t>(index));
    result.phase(msg::PHASE_EVALUATION);
    dds::seal(result);
    link->results().write(result);
  }

  int run(const std::atomic<bool>& stop) {
    std::filesystem::create_directories(config.run_dir() / "eval");
    if (continuous) return run_continuous(stop);
    std::uint64_t version = 0;
    if (!policy) {
      // A learner's snapshot over DDS.
      const auto start = Clock::now();
      const double timeout_s = eval.snapshot_timeout_s;
      auto snapshot = wait_for_snapshot(stop, 0, eval.wait_for_done, timeout_s);
      if (snapshot == nullptr) {
        if (stop.load()) return 0;
        INDRIVE_LOG(kError, "evaluator")
            << "no policy snapshot arrived within " << timeout_s << " s; is the learner of run '"
            << config.run_id() << "' running on domain " << config.domain_id() << "?";
        return 2;
      }
      load(*snapshot);
      version = snapshot->version();
      // Kept so the same snapshot can be evaluated again without a learner (--snapshot FILE).
      agent::write_snapshot_file(
          config.run_dir() / "eval" / ("snapshot-v" + std::to_string(version) + ".params"),
          snapshot->params(), agent_config);
      INDRIVE_LOG(kInfo, "evaluator")
          << "evaluator " << index << "/" << count << " evaluates snapshot v" << version
          << ", received " << std::chrono::duration<double>(Clock::now() - start).count()
          << " s after start";
    }
    EpisodeCsvWriter csv(results_file());  // first: it cuts a row a crash left unfinished
    run_episodes(stop, version, 0, &csv, nullptr, finished_episodes(version));
    if (link) link->results().wait_for_acknowledgments(std::chrono::seconds(2));
    return 0;
  }

  int run_continuous(const std::atomic<bool>& stop) {
    const int every_k = eval.every_k;
    const double timeout_s = eval.snapshot_timeout_s;
    CurveWriter curve(config.run_dir() / "eval" / ("curve-" + std::to_string(index) + ".csv"));
    std::uint64_t evaluated = 0;
    int evaluations = 0;
    bool final_from_file = false;
    while (!stop.load()) {
      const std::uint64_t last = final_version();
      if (last > 0 && evaluated >= last) break;
      // The next snapshot at least every_k versions on, or the final one, whichever comes.
      std::shared_ptr<const msg::PolicySnapshot> next;
      const auto start = Clock::now();
      while (!stop.load() && next == nullptr) {
        auto newest = link->inbox().take_newer_than(evaluated);
        const std::uint64_t done_version = final_version();
        if (newest != nullptr && (evaluated == 0 || newest->version() >= evaluated + every_k ||
                                  (done_version > 0 && newest->version() >= done_version))) {
          next = newest;
          break;
        }
        if (done_version > 0 && evaluated >= done_version) break;
        // The run's end from the learner's file when it did not come over DDS (as in run()).
        if (done_version > 0 || learner_silent(start)) {
          next = final_snapshot_from_file(evaluated,
                                          std::max(done_version, newest ? newest->version() : 0));
          if (next != nullptr) {
            final_from_file = true;
            break;
          }
        }
        if (evaluated > 0 && learner_silent(start)) {
          // The curve ends with the newest snapshot held, evaluated once.
          if (newest != nullptr) {
            warn_evaluating_unannounced(newest->version());
            next = newest;
          } else {
            warn_silent_learner("the learning curve ends at v" + std::to_string(evaluated));
          }
          break;
        }
        if (link->inbox().should_request(newest ? newest->version() : evaluated, Clock::now())) {
          link->request_snapshot();
        }
        if (std::chrono::duration<double>(Clock::now() - start).count() > timeout_s) {
          INDRIVE_LOG(kError, "evaluator")
              << "no new snapshot within " << timeout_s << " s after v" << evaluated;
          return evaluations > 0 ? 0 : 2;
        }
        std::this_thread::sleep_for(std::chrono::milliseconds(20));
      }
      if (next == nullptr) break;
      load(*next);
      INDRIVE_LOG(kInfo, "evaluator")
          << "evaluator " << index << " evaluates snapshot v" << next->version() << " at "
          << next->env_steps() << " env steps for the learning curve";
      run_episodes(stop, next->version(), next->env_steps(), nullptr, &curve);
      evaluated = next->version();
      ++evaluations;
      if (final_from_file) break;  // the learner has ended: nothing newer will come
    }
    if (link) link->results().wait_for_acknowledgments(std::chrono::seconds(2));
    return 0;
  }

  std::filesystem::path results_file() const {
    return config.run_dir() / "eval" / ("evaluator-" + std::to_string(index) + ".csv");
  }

  const service::ServiceConfig& config;
  const EvalConfig eval;             // the eval.* keys, read once
  const ActorConfig actor_settings;  // the actor.* keys, read once
  int index;
  int count;
  agent::AgentConfig agent_config;
  ProtocolGrid grid;
  PolicySource source = PolicySource::kSnapshot;
  PolicyHead head = PolicyHead::kExploration;
  std::filesystem::path snapshot_file;
  bool continuous = false;
  std::string method;
  std::string task;
  std::unique_ptr<EpisodePolicy> policy;
  // The modification time of the final snapshot file last read (it is read again only when it
  // changes).
  std::filesystem::file_time_type final_file_seen{};
  std::unique_ptr<env::Env> env;
  // The link to the learner when a learner's snapshots are evaluated (nullptr otherwise). Last:
  // its readers' callbacks go before anything else does.
  std::unique_ptr<LearnerLink> link;
};

Evaluator::Evaluator(const service::ServiceConfig& config, int index, int count)
    : impl_(std::make_unique<Impl>(config, index, count)) {}
Evaluator::~Evaluator() = default;
int Evaluator::run(const std::atomic<bool>& stop) { return impl_->run(stop); }
std::filesystem::path Evaluator::results_file() const { return impl_->results_file(); }

}  // namespace indrive::actor
