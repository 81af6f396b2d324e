// The driving environment seen through the agent's minimal interface: env::Env episodes as
// agent::Environment steps (class-id frames at the preset's image size, the task reward in task
// phases, is_last / is_terminal), with the episode choices a training actor makes (a route or
// random spawns, a density redrawn every density period, fresh traffic and spawn seeds per
// episode, all from one seed).
//
//   env::Env env(env_config(service));
//   EnvAdapter adapter(env, EnvAdapter::options_from(service));
//   adapter.on_result([&](const env::StepResult& r) { coverage.observe(r.ego.pose); });
//   adapter.on_episode([&](const EpisodeRecord& e) { csv.write(e); });  // each finished one
//   LocalTrainer trainer(service.agent(), adapter);
#pragma once

#include <cstdint>
#include <functional>
#include <random>
#include <string>
#include <vector>

#include "indrive/actor/eval_protocol_record.h"
#include "indrive/agent/local_trainer.h"
#include "indrive/envserver/env.h"
#include "indrive/service/run_config.h"

namespace indrive::actor {

// The environment of a training actor from a run's env.* keys: the town, the image size of the
// agent's preset, the task in task phases.
env::EnvConfig env_config(const service::ServiceConfig& service);
// The same for another agent configuration (an evaluator's, sized by its snapshot file).
env::EnvConfig env_config(const service::ServiceConfig& service, const agent::AgentConfig& agent);
// The town options of a run's configuration (env.route_set).
env::TownOptions town_options(const config::Config& config);

// The routes named by `env.route`: none (empty text: random spawns, pretraining), one name, or
// a comma-separated list (task phases on several fixed routes, as the paper fine-tunes on the
// training town's routes). Spaces around names are dropped; throws std::invalid_argument for
// an empty name in a list ("a,,b").
std::vector<std::string> route_list(const std::string& text);

// The route of the next episode: the only one, or one drawn uniformly from several; draws
// from `rng` only when there is a choice, so a one-route run's seeds are unchanged.
std::string draw_route(const std::vector<std::string>& routes, std::mt19937_64& rng);

// Episode choices of the adapter.
struct EnvAdapterOptions {
  std::string town;   // env.town, as finished episodes name it
  std::string route;  // env.route: empty (random spawns), one route or a comma-separated list
  std::vector<double> densities = {10};  // drawn uniformly every density_period_steps
  std::int64_t density_period_steps = 10000;
  std::uint64_t seed = 0;            // seeds densities, traffic and spawns
  double coverage_segment_m = 10.0;  // env.coverage_segment_m: the coverage tracker's segments
};

class EnvAdapter : public agent::Environment {
 public:
  // The environment must outlive the adapter. Throws std::invalid_argument for an empty
  // density list or a period below 1.
  EnvAdapter(env::Env& env, EnvAdapterOptions options);
  // The options a training actor of this run uses (env.town, env.route, env.densities,
  // env.density_period_steps, run.seed, env.coverage_segment_m).
  static EnvAdapterOptions options_from(const service::ServiceConfig& config);

  // Starts an episode with the next density and fresh seeds; returns its first frame.
  agent::EnvStep reset() override;
  // Applies action in [0, 9) and returns the next frame; the reward is the env's task reward
  // (0 in pretraining).
  agent::EnvStep step(int action) override;

  // Calls `observer` with every env result (after each reset and step), e.g. for coverage.
  void on_result(std::function<void(const env::StepResult&)> observer) {
    observer_ = std::move(observer);
  }
  // Calls `observer` with each finished episode's record (training_record: the verdict, route
  // completion and return; the caller adds the run-level fields), after on_result's call.
  void on_episode(std::function<void(const EpisodeRecord&)> observer) {
    episode_observer_ = std::move(observer);
  }
  // The env result of the last reset or step.
  const env::StepResult& last() const { return last_; }
  // Frames returned so far (resets and steps), the unit of the density period.
  std::int64_t frames() const { return frames_; }
  int density() const { return density_; }

 private:
  agent::EnvStep convert(const env::StepResult& result);

  env::Env& env_;
  EnvAdapterOptions options_;
  std::vector<std::string> routes_;
  std::mt19937_64 rng_;
  std::function<void(const env::StepResult&)> observer_;
  std::function<void(const EpisodeRecord&)> episode_observer_;
  TrainingEpisode episode_;  // the running episode's choices and return
  env::StepResult last_;
  std::int64_t frames_ = 0;
  std::int64_t next_density_draw_ = 0;
  int density_ = 10;
};

}  // namespace indrive::actor
