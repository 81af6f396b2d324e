#include "indrive/actor/env_adapter.h"

#include <stdexcept>

#include "indrive/basics/check.h"

namespace indrive::actor {

env::EnvConfig env_config(const service::ServiceConfig& service) {
  return env_config(service, service.agent());
}

env::EnvConfig env_config(const service::ServiceConfig& service, const agent::AgentConfig& agent) {
  const config::Config& config = service.config();
  env::EnvConfig env;
  env.town = config.get<std::string>("env.town");
  env.sumo.mode = config.get<std::string>("env.sumo_mode") == "libtraci" ? env::SumoMode::kLibtraci
                                                                         : env::SumoMode::kLibsumo;
  env.camera.width = agent.world_model.image;
  env.camera.height = agent.world_model.image;
  env.events.time_limit_steps = config.get<int>("env.time_limit_steps");
  env.town_options = town_options(config);
  if (agent.phase != agent::Phase::kPretrain) env.task = agent.task;
  return env;
}

env::TownOptions town_options(const config::Config& config) {
  env::TownOptions options;
  options.route_set = config.get<std::string>("env.route_set");
  return options;
}

std::vector<std::string> route_list(const std::string& text) {
  std::vector<std::string> out;
  if (text.find_first_not_of(" \t") == std::string::npos) return out;
  std::size_t begin = 0;
  while (true) {
    const std::size_t end = text.find(',', begin);
    std::string name =
        text.substr(begin, end == std::string::npos ? std::string::npos : end - begin);
    name.erase(0, name.find_first_not_of(" \t"));
    name.erase(name.find_last_not_of(" \t") + 1);
    if (name.empty()) {
      throw std::invalid_argument("env.route '" + text +
                                  "' has an empty name; give route names separated by commas, "
                                  "e.g. straight,right_loop");
    }
    out.push_back(std::move(name));
    if (end == std::string::npos) return out;
    begin = end + 1;
  }
}

std::string draw_route(const std::vector<std::string>& routes, std::mt19937_64& rng) {
  if (routes.empty()) return "";
  if (routes.size() == 1) return routes.front();
  return routes[rng() % routes.size()];
}

EnvAdapter::EnvAdapter(env::Env& env, EnvAdapterOptions options)
    : env_(env),
      options_(std::move(options)),
      routes_(route_list(options_.route)),
      rng_(options_.seed * 7919u + 17u) {
  if (options_.densities.empty()) {
    throw std::invalid_argument("env.densities is empty: give at least one of 0, 5, 10, 20");
  }
  if (options_.density_period_steps < 1) {
    throw std::invalid_argument("env.density_period_steps must be at least 1");
  }
}

EnvAdapterOptions EnvAdapter::options_from(const service::ServiceConfig& config) {
  const auto& c = config.config();
  return {.town = c.get<std::string>("env.town"),
          .route = c.get<std::string>("env.route"),
          .densities = c.get<std::vector<double>>("env.densities"),
          .density_period_steps = c.get<std::int64_t>("env.density_period_steps"),
          .seed = static_cast<std::uint64_t>(c.get<std::int64_t>("run.seed")),
          .coverage_segment_m = c.get<double>("env.coverage_segment_m")};
}

agent::EnvStep EnvAdapter::convert(const env::StepResult& result) {
  last_ = result;
  ++frames_;
  episode_.episode_return += result.reward.value_or(0.0);
  if (observer_) observer_(result);
  if (result.is_last && episode_observer_) episode_observer_(training_record(episode_, result));
  agent::EnvStep step;
  step.frame.assign(result.observation.data, result.observation.data + result.observation.total());
  step.reward = static_cast<float>(result.reward.value_or(0.0));
  step.is_last = result.is_last;
  step.is_terminal = result.is_terminal;
  return step;
}

agent::EnvStep EnvAdapter::reset() {
  // As the training actor: the density is redrawn every period, the seeds every episode.
  if (frames_ >= next_density_draw_) {
    density_ = static_cast<int>(options_.densities[rng_() % options_.densities.size()]);
    next_density_draw_ += options_.density_period_steps;
  }
  const std::uint64_t traffic_seed = rng_() % 1000000u;
  const std::uint64_t spawn_seed = rng_() % 1000000u;
  const std::string route = draw_route(routes_, rng_);
  env::StepResult first = env_.reset({.route = route,
                                      .density = density_,
                                      .traffic_seed = traffic_seed,
                                      .spawn_seed = spawn_seed});
  const env::Route* driven = env_.route();
  episode_ = {.town = options_.town,
              .route = route,
              .density = density_,
              .traffic_seed = static_cast<int>(traffic_seed),
              .spawn_seed = static_cast<int>(spawn_seed),
              .route_length_m = driven == nullptr ? 0.0 : driven->length_m()};
  return convert(first);
}

agent::EnvStep EnvAdapter::step(int action) {
  INDRIVE_CHECK(action >= 0 && action < agent::kNumActions) << "action " << action;
  return convert(env_.step(action));
}

}  // namespace indrive::actor
