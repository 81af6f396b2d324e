#include "indrive/agent/local_trainer.h"

#include "indrive/basics/check.h"

namespace indrive::agent {

namespace {
ReplayOptions replay_options(const AgentConfig& c) {
  return {.capacity = c.replay.capacity,
          .height = c.world_model.image,
          .width = c.world_model.image,
          .num_classes = 8,
          .num_actions = kNumActions,
          .has_rewards = c.phase != Phase::kPretrain,
          .seed = c.replay.seed};
}
}  // namespace

LocalTrainer::LocalTrainer(const AgentConfig& config, Environment& env, LocalTrainerOptions options)
    : config_(config),
      env_(env),
      options_(options),
      rate_({.replay_ratio = options.train_ratio,
             .steps_per_update =
                 static_cast<std::int64_t>(config.replay.batch) * config.replay.length}),
      agent_(config),
      replay_(replay_options(config)),
      policy_(config),
      random_(config.seed + 1) {
  refresh_policy();
}

void LocalTrainer::refresh_policy() { policy_.load_snapshot(agent_.snapshot()); }

void LocalTrainer::run(std::int64_t env_steps,
                       const std::function<void(const TrainMetrics&)>& on_metrics,
                       const std::atomic<bool>* stop) {
  const bool keep_rewards = config_.phase != Phase::kPretrain;
  const auto stopped = [stop] { return stop != nullptr && stop->load(); };
  for (std::int64_t i = 0; i < env_steps && !stopped(); ++i) {
    if (need_reset_) {
      current_ = env_.reset();
      need_reset_ = false;
      first_ = true;
      return_ = 0.0;
    }
    const bool prefill = replay_.total_added() < config_.replay.prefill;
    const int action = prefill ? random_.act() : policy_.act(current_.frame, first_, state_, true);
    if (prefill) state_.action = action;  // keeps the policy's previous action consistent
    ReplayStep step;
    step.frame = current_.frame;
    step.action = action;
    step.is_first = first_;
    step.is_last = current_.is_last;
    step.is_terminal = current_.is_terminal;
    // Pretraining never stores a task reward: the field stays zero.
    step.reward = keep_rewards ? current_.reward : 0.0f;
    replay_.add(0, step);
    ++counters_.env_steps;
    if (current_.is_last) {
      // The last frame is stored with its action ignored; the next step starts an episode.
      counters_.episode_return = return_;
      ++counters_.episodes;
      need_reset_ = true;
    } else {
      current_ = env_.step(action);
      return_ += current_.reward;
      first_ = false;
    }
    // Train while updates are due at the replay ratio, over the whole run.
    while (!prefill && !stopped() && replay_.num_windows(config_.replay.length) > 0 &&
           earlier_updates_ + counters_.updates <
               rate_.updates_due(earlier_env_steps_ + counters_.env_steps)) {
      const TrainMetrics metrics =
          agent_.train_step(replay_.sample(config_.replay.batch, config_.replay.length));
      ++counters_.updates;
      if (counters_.updates % options_.snapshot_every == 0) refresh_policy();
      if (on_metrics) on_metrics(metrics);
    }
  }
}

void LocalTrainer::save(const std::filesystem::path& dir) const {
  std::error_code error;
  std::filesystem::create_directories(dir, error);
  if (error)
    throw AgentError("cannot create checkpoint folder " + dir.string() + ": " + error.message());
  agent_.save_checkpoint(dir / "agent.ckpt");
  replay_.save(dir / "replay.bin");
}

void LocalTrainer::load(const std::filesystem::path& dir) {
  agent_.load_checkpoint(dir / "agent.ckpt");
  const std::filesystem::path replay_file = dir / "replay.bin";
  if (std::filesystem::exists(replay_file)) {
    try {
      replay_.load(replay_file);
    } catch (const ReplayError&) {
      // A pretraining replay (no rewards) cannot seed a task phase; start with an empty one.
      if (config_.phase == Phase::kPretrain) throw;
    }
  }
  refresh_policy();
}

void LocalTrainer::load_agent(std::span<const std::uint8_t> bytes, const std::string& name) {
  agent_.load_checkpoint(bytes, name);
  refresh_policy();
}

}  // namespace indrive::agent
