#include "indrive/local/local_run.h"

#include <chrono>
#include <cmath>
#include <limits>
#include <map>
#include <nlohmann/json.hpp>
#include <optional>
#include <sstream>

#include "indrive/actor/actor_config.h"
#include "indrive/actor/env_adapter.h"
#include "indrive/actor/eval_protocol.h"
#include "indrive/actor/eval_protocol_episode.h"
#include "indrive/actor/eval_protocol_record.h"
#include "indrive/actor/policies.h"
#include "indrive/agent/local_trainer.h"
#include "indrive/agent/snapshot_file.h"
#include "indrive/basics/check.h"
#include "indrive/basics/episode_csv.h"
#include "indrive/basics/log.h"
#include "indrive/basics/run_dir.h"
#include "indrive/basics/stopwatch.h"
#include "indrive/envserver/town.h"
#include "indrive/learner/learner.h"
#include "indrive/learner/learner_config.h"
#include "indrive/learner/training_episodes.h"
#include "indrive/nn/kernels.h"
#include "indrive/service/training_metrics.h"

namespace indrive::local {
namespace fs = std::filesystem;
namespace {


RunDir open_run(const service::ServiceConfig& config) {
  return RunDir::open_or_create(
      config.run_dir().parent_path().empty() ? fs::path(".") : config.run_dir().parent_path(),
      config.run_id());
}

// The local.* settings, the keys only indrive-train-local reads.
struct LocalSettings {
  bool random = false;  // local.random: uniform random actions, no training (the baseline)
};
LocalSettings local_settings(const config::Config& config) {
  return {.random = config.get<bool>("local.random")};
}

// The agent's config for this process: random mode never leaves prefill, so it never trains.
// A finetune without a checkpoint to start from is refused here, before SUMO starts.
agent::AgentConfig local_agent_config(const service::ServiceConfig& config,
                                      const LocalSettings& local,
                                      const learner::LearnerConfig& settings) {
  agent::AgentConfig agent = config.training_agent("local");
  const bool resumable = CheckpointFiles(open_run(config).checkpoints(), 1000).newest().has_value();
  if (agent.phase == agent::Phase::kFinetune && !local.random && !resumable &&
      settings.init_checkpoint.empty()) {
    throw LocalRunError(
        "finetune needs a pretrained agent: set learner.init_checkpoint to a pretraining "
        "run's checkpoint, e.g. --set learner.init_checkpoint=runs/<run>/checkpoints/"
        "ckpt-000000000100.bin");
  }
  if (local.random) {
    agent.replay.prefill = std::numeric_limits<std::int64_t>::max();
  }
  return agent;
}

// The environment, started on the first reset: a run that only reloads or reports never
// starts SUMO (libsumo allows one simulation per process).
class LazyEnvironment : public agent::Environment {
 public:
  LazyEnvironment(env::EnvConfig env_config, actor::EnvAdapterOptions options,
                  std::function<void(const env::StepResult&)> observer,
                  std::function<void(const EpisodeRecord&)> episode_observer)
      : env_config_(std::move(env_config)),
        options_(options),
        observer_(std::move(observer)),
        episode_observer_(std::move(episode_observer)) {}

  agent::EnvStep reset() override {
    if (!adapter_) {
      env_ = std::make_unique<env::Env>(env_config_);
      adapter_ = std::make_unique<actor::EnvAdapter>(*env_, options_);
      adapter_->on_result(observer_);
      adapter_->on_episode(episode_observer_);
    }
    return adapter_->reset();
  }
  agent::EnvStep step(int action) override { return adapter_->step(action); }

 private:
  const env::EnvConfig env_config_;
  const actor::EnvAdapterOptions options_;
  std::function<void(const env::StepResult&)> observer_;
  std::function<void(const EpisodeRecord&)> episode_observer_;
  std::unique_ptr<env::Env> env_;
  std::unique_ptr<actor::EnvAdapter> adapter_;
};

std::string method_name(const LocalSettings& local, const agent::AgentConfig& agent) {
  return local.random ? "random" : agent::method_label(agent);
}

}  // namespace

struct LocalRun::Impl {
  explicit Impl(const service::ServiceConfig& service)
      : config(service),
        settings(learner::learner_config(service.config())),
        local(local_settings(service.config())),
        agent_config(local_agent_config(service, local, settings)),
        run(open_run(service)),
        checkpoints(run.checkpoints(), settings.checkpoint_keep, "local", settings.checkpoint_s),
        env_config(actor::env_config(service)),
        town(env::load_town(env_config.town, env_config.town_options)),
        adapter_options(actor::EnvAdapter::options_from(service)),
        coverage(town.net, {.segment_m = adapter_options.coverage_segment_m}),
        environment(
            env_config, adapter_options,
            [this](const env::StepResult& result) {
              if (result.is_first) close_episode();
              coverage.observe(result.ego.pose);
            },
            [this](const EpisodeRecord& record) { write_training_episode(record); }),
        trainer(agent_config, environment,
                {.train_ratio = settings.replay_ratio,
                 .snapshot_every = static_cast<int>(settings.snapshot_every)}),
        metrics(run.metrics_path()) {
    service.config().write_yaml(run.config_path());
    INDRIVE_LOG(kInfo, "local") << nn::kernel_report();
    service.note_agent_precision(trainer.agent(), "local");
    resume();
  }

  // Starts where start_run says, as the learner does: the newest intact checkpoint (agent,
  // replay, counters), else the finetune's initial checkpoint, else nothing.
  void resume() {
    learner::RunStart start =
        learner::start_run(checkpoints.files().list(), settings.init_checkpoint, agent_config,
                           trainer.replay().options(), config.run_id());
    base = start.restored.counters;
    if (start.restored.agent) {
      trainer.load_agent(start.restored.agent->checkpoint_bytes(), start.restored.file.string());
    }
    if (start.from != learner::StartedFrom::kCheckpoint) return;
    checkpoints.resumed_from(start.restored.file);
    // The replay goes on where it stopped: no second random prefill in the middle of a run.
    trainer.replay() = std::move(*start.restored.replay);
    restore_coverage();
    // The ratio is kept over the whole run: what a session stopped during a catch-up still
    // owed is trained first. The random baseline never trains.
    if (!local.random) trainer.continue_from(base.env_steps, base.updates);
    INDRIVE_LOG(kInfo, "local") << "resumed from " << start.restored.file.string() << " at "
                                << base.env_steps << " env steps, " << base.updates << " updates, "
                                << trainer.replay().size() << " replay steps";
  }

  // A resumed run continues the coverage of its earlier sessions (coverage.csv).
  void restore_coverage() {
    const fs::path file = run.path() / "coverage.csv";
    if (!fs::exists(file)) return;
    const env::CoverageCounts counts = env::read_coverage_csv({file});
    if (counts.segment_m != coverage.options().segment_m) {
      INDRIVE_LOG(kWarn, "local") << "coverage.csv has " << counts.segment_m
                                  << " m segments, this run " << coverage.options().segment_m
                                  << " m: coverage starts afresh";
      return;
    }
    coverage.restore(counts);
  }

  std::int64_t env_steps() const { return base.env_steps + trainer.counters().env_steps; }
  std::int64_t updates() const { return base.updates + trainer.counters().updates; }

  // Writes a checkpoint as the learner does (learner::CheckpointWriter); returns whether it was
  // written. `final`: the one at the end, which has no next try.
  bool save_checkpoint(bool final) {
    learner::LearnerCounters counters = base;
    counters.env_steps = env_steps();
    counters.updates = updates();
    counters.policy_version = static_cast<std::uint64_t>(counters.updates);
    // With the replay, as the learner's: a resumed run trains on the data it had (the random
    // baseline never trains, so its replay is not kept).
    const std::vector<std::uint8_t> replay_bytes =
        local.random ? std::vector<std::uint8_t>{} : trainer.replay().to_bytes();
    return checkpoints.save(counters, trainer.agent().checkpoint_bytes(), replay_bytes,
                            local.random ? 0 : trainer.replay().size(), final);
  }

  // The final checkpoint, which must be written: what was trained since the last one is lost
  // otherwise.
  void save_final_checkpoint() {
    if (save_checkpoint(/*final=*/true)) return;
    throw IoError(
        "the final checkpoint could not be written (see the error above): a restart "
        "resumes from " +
        (checkpoints.latest().empty() ? std::string("nothing (this run has none)")
                                      : checkpoints.latest().string()) +
        " and what was trained after it is lost; free disk space and run again");
  }

  void on_update(const agent::TrainMetrics& step) {
    for (const auto& [name, value] : step) {
      auto& [sum, count] = interval_sums[name];
      if (std::isfinite(value)) {
        sum += value;
        ++count;
      } else {
        ++non_finite;  // counted and logged: a diverging loss must be visible, not averaged in
      }
    }
  }

  service::TrainingProgress progress_now() {
    return {.env_steps = env_steps(),
            .updates = updates(),
            .policy_version = static_cast<std::uint64_t>(updates()),
            .learner_epoch = base.learner_epoch,
            .replay_size = trainer.replay().size(),
            .steps_per_update =
                static_cast<std::int64_t>(agent_config.replay.batch) * agent_config.replay.length,
            .phase = agent_config.phase};
  }

  void log_metrics() {
    const service::TrainingProgress now = progress_now();
    const auto& counters = trainer.counters();
    nlohmann::json record = interval.fields(now);
    record.update({{"episodes", counters.episodes - logged_episodes},
                   {"random_policy", local.random},
                   {"non_finite_metrics", non_finite},
                   {"coverage_distinct_per_1k", coverage.distinct_per_window()},
                   {"coverage_fraction_visited", coverage.fraction_visited()},
                   {"coverage_segments_visited", coverage.segments_visited()}});
    if (counters.episodes > logged_episodes) record["episode_return"] = counters.episode_return;
    episodes.write(record);  // length and reach, see close_episode()
    // Training metrics as means over the interval's updates (the learner logs its last update;
    // a mean is steadier for the few updates of a local run).
    for (const auto& [name, sum_count] : interval_sums) {
      if (sum_count.second > 0) record[name] = sum_count.first / sum_count.second;
    }
    metrics.write(record);

    std::ostringstream line;
    line.precision(4);
    line << interval.console_head(now);
    for (const char* key : {"wm/recon", "wm/kl", "intrinsic/loss", "expl/reward", "expl/entropy",
                            "wm/reward", "task/reward", "task/actor_loss", "task/entropy"}) {
      if (record.contains(key)) line << " | " << key << " " << record[key].get<double>();
    }
    line << " | coverage " << coverage.distinct_per_window() << " seg/1k, "
         << 100.0 * coverage.fraction_visited() << "% of town";
    if (progress) progress(line.str());
    interval_sums.clear();
    interval.restart(now);
    logged_episodes = counters.episodes;
  }

  // One row of train-episodes.csv per finished training episode (a resumed run keeps the rows
  // of the episodes after its last checkpoint, as metrics.jsonl keeps their lines).
  void write_training_episode(EpisodeRecord record) {
    record.run_id = config.run_id();
    record.policy_version = updates();
    train_episodes.write(std::move(record));
  }

  // Closes the coverage tracker's episode (the steps observed since the last reset) and counts
  // its length and reach for metrics.jsonl.
  void close_episode() {
    const std::size_t closed = coverage.episode_reach().size();
    coverage.end_episode();
    if (coverage.episode_reach().size() > closed) {
      episodes.add(coverage.episode_steps().back(), coverage.episode_reach().back());
    }
  }

  void train(const std::atomic<bool>& stop) {
    interval.restart(progress_now());
    const auto on_metrics = [this](const agent::TrainMetrics& step) {
      on_update(step);
      on_update(trainer.agent().last_timing().as_metrics());
    };
    const std::int64_t budget = settings.budget_env_steps;
    while (!stop.load() && (budget <= 0 || env_steps() < budget)) {
      // Small slices keep the stop signal, logging and checkpoints responsive.
      const std::int64_t slice = budget > 0 ? std::min<std::int64_t>(16, budget - env_steps()) : 16;
      trainer.run(slice, on_metrics, &stop);
      if (interval.due(progress_now(), settings.log_interval_s, settings.log_every_env_steps))
        log_metrics();
      if (checkpoints.seconds_since_save() >= settings.checkpoint_s) save_checkpoint(false);
    }
    // A session that took no step (budget already reached) leaves the files of the last one.
    if (trainer.counters().env_steps == 0) return;
    if (env_steps() != interval.start_env_steps()) log_metrics();
    save_final_checkpoint();
    // The acting policy as a snapshot file, evaluable without this run directory
    // (indrive-actor --evaluate --snapshot FILE).
    agent::write_snapshot_file(run.path() / "snapshot.params", trainer.agent().snapshot(),
                               agent_config);
    coverage.write_csv(run.path() / "coverage.csv");
    INDRIVE_LOG(kInfo, "local") << (stop.load() ? "stopped" : "budget reached") << ": "
                                << env_steps() << " env steps, " << updates() << " updates, "
                                << "coverage " << coverage.distinct_per_window()
                                << " distinct segments per 1k steps, "
                                << 100.0 * coverage.fraction_visited() << "% of the town";
  }

  const service::ServiceConfig& config;
  const learner::LearnerConfig settings;  // the learner.* and run.* keys, read once
  const LocalSettings local;              // the local.* keys
  agent::AgentConfig agent_config;
  RunDir run;
  learner::CheckpointWriter checkpoints;
  const env::EnvConfig env_config;
  env::Town town;  // for coverage; the Env loads its own copy when it starts
  const actor::EnvAdapterOptions adapter_options;
  env::CoverageTracker coverage;
  EpisodeStats episodes;  // length and reach of the episodes the coverage tracker closed
  LazyEnvironment environment;
  agent::LocalTrainer trainer;
  MetricsLog metrics;
  learner::LearnerCounters base;
  std::map<std::string, std::pair<double, std::int64_t>> interval_sums;
  std::int64_t non_finite = 0;
  std::function<void(const std::string&)> progress;
  service::MetricsInterval interval;  // since the last metrics line
  std::int64_t logged_episodes = 0;
  learner::TrainingEpisodes train_episodes{run.train_episodes_path(),
                                           {.method = method_name(local, agent_config),
                                            .task = agent::task_label(agent_config),
                                            .train_seed = static_cast<int>(settings.seed)},
                                           "local"};
};

LocalRun::LocalRun(const service::ServiceConfig& config) : impl_(std::make_unique<Impl>(config)) {}
LocalRun::~LocalRun() = default;
void LocalRun::on_progress(std::function<void(const std::string&)> callback) {
  impl_->progress = std::move(callback);
}
void LocalRun::train(const std::atomic<bool>& stop) { impl_->train(stop); }
void LocalRun::save_checkpoint() { impl_->save_final_checkpoint(); }
std::int64_t LocalRun::env_steps() const { return impl_->env_steps(); }
std::int64_t LocalRun::updates() const { return impl_->updates(); }
agent::Agent& LocalRun::agent() { return impl_->trainer.agent(); }
const env::CoverageTracker& LocalRun::coverage() const { return impl_->coverage; }

EvaluationSummary evaluate_locally(const service::ServiceConfig& config, const std::string& route,
                                   int episodes, const std::atomic<bool>& stop) {
  const agent::AgentConfig agent_config = config.agent();
  const LocalSettings local = local_settings(config.config());
  const learner::LearnerConfig settings = learner::learner_config(config.config());
  const env::EnvConfig env_config = actor::env_config(config);
  const RunDir run = open_run(config);

  // The acting policy of the newest checkpoint, or uniform random actions in random mode, as
  // the evaluator drives them (one policy seed per episode).
  std::unique_ptr<actor::EpisodePolicy> policy;
  long long version = 0;
  if (local.random) {
    policy = actor::make_random_policy(static_cast<std::uint64_t>(settings.seed));
  } else {
    const std::vector<fs::path> files = CheckpointFiles(run.checkpoints(), 1000).list();
    if (files.empty()) {
      throw LocalRunError("no checkpoint in " + run.checkpoints().string() +
                          ": train the run first (indrive-train-local without "
                          "--evaluate-episodes), or pass --random for the random baseline");
    }
    // The newest that loads: a damaged newest one (a crash while writing it) is skipped.
    const learner::RestoredRun loaded = learner::load_newest_agent(files, agent_config);
    version = loaded.counters.updates;
    const agent::Agent& agent = *loaded.agent;
    const std::string name = loaded.file.string();
    const actor::PolicyHead head = agent_config.phase == agent::Phase::kPretrain
                                       ? actor::PolicyHead::kExploration
                                       : actor::PolicyHead::kTask;
    policy = actor::make_snapshot_policy(agent_config, agent.snapshot(), head, name);
    INDRIVE_LOG(kInfo, "local") << "evaluating " << agent.acting_actor_group() << " of " << name;
  }

  actor::ProtocolGrid grid;
  const std::string town = env_config.town;
  const actor::EvalConfig eval = actor::eval_config(config.config());
  grid.towns = {town};
  grid.routes = {route};
  grid.densities.clear();
  for (const double d : eval.densities) {
    grid.densities.push_back(static_cast<int>(d));
  }
  grid.episodes_per_cell = episodes;
  grid.validate();

  // As in the evaluator, episodes end at the route's own step budget (below).
  env::Env env(actor::protocol_env_config(env_config, actor::parse_protocol(eval.protocol)));
  EpisodeCsvWriter csv(run.eval() /
                       ("local-" + actor::town_file_label(town) + "-" + route + ".csv"));
  EvaluationSummary summary;
  double completion_sum = 0.0, steps_sum = 0.0;
  const actor::ProtocolEpisodeOptions options =
      actor::protocol_episode_options(config.config(), run.videos());
  for (const actor::EpisodeSpec& spec : grid.all_episodes()) {
    if (stop.load()) break;
    const actor::EpisodeOutcome outcome =
        actor::run_protocol_episode(env, *policy, spec, options, stop);
    if (outcome.stopped) break;
    EpisodeRecord record = actor::protocol_record(spec, outcome);
    record.run_id = config.run_id();
    record.method = method_name(local, agent_config);
    record.eval_kind = agent_config.phase == agent::Phase::kPretrain ? "zero_shot" : "few_shot";
    record.task = agent::task_label(agent_config);
    record.train_seed = static_cast<int>(settings.seed);
    record.policy_version = version;
    csv.write(record);
    if (record.failure_reason == "env_fault") {  // SUMO failed: nothing of the policy
      INDRIVE_LOG(kWarn, "local") << "episode at density " << spec.density
                                  << " ended by a SUMO fault; not counted";
      continue;
    }
    ++summary.episodes;
    summary.successes += record.success ? 1 : 0;
    completion_sum += record.route_completion;
    steps_sum += record.steps;
    INDRIVE_LOG(kInfo, "local") << "episode " << summary.episodes << ": density " << spec.density
                                << ", " << (record.success ? "success" : record.failure_reason)
                                << ", " << record.steps << " steps, completion "
                                << record.route_completion;
  }
  if (summary.episodes > 0) {
    summary.success_rate = static_cast<double>(summary.successes) / summary.episodes;
    summary.mean_route_completion = completion_sum / summary.episodes;
    summary.mean_steps = steps_sum / summary.episodes;
  }
  return summary;
}

}  // namespace indrive::local
