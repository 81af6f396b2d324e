#include "indrive/actor/policies.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <optional>
#include <random>
#include <utility>

#include "indrive/agent/policy.h"
#include "indrive/basics/check.h"
#include "indrive/envserver/events.h"
#include "indrive/envserver/follower.h"
#include "indrive/envserver/town.h"
#include "text.h"

namespace indrive::actor {
namespace {

class SnapshotPolicy final : public EpisodePolicy {
 public:
  SnapshotPolicy(const agent::AgentConfig& config, std::span<const std::uint8_t> blob)
      : policy_(config) {
    policy_.load_snapshot(blob);
  }
  void begin(const env::Env&, const EpisodeSpec& spec) override {
    state_ = {};
    policy_.reseed(spec.policy_seed);
  }
  int act(const env::Env&, const env::StepResult& result) override {
    return policy_.act_eval(
        std::span<const std::uint8_t>(result.observation.data, result.observation.total()),
        result.is_first, state_);
  }

 private:
  agent::Policy policy_;
  agent::PolicyState state_;
};

class OraclePolicy final : public EpisodePolicy {
 public:
  explicit OraclePolicy(const OracleOptions& options) : options_(options) {}
  void begin(const env::Env& env, const EpisodeSpec& spec) override {
    if (env.route() == nullptr) {
      throw EvalError("the oracle policy needs a route; episode of town " + spec.town +
                      " has none");
    }
    follower_.emplace(*env.route(), env.config().ego,
                      env::FollowerConfig{.target_speed_mps = options_.target_speed_mps});
    follower_->reset();
    s_m_ = 0.0;
    previous_.clear();
  }
  int act(const env::Env& env, const env::StepResult& result) override {
    const int action = follower_->act(result.ego);
    if (!options_.brake_for_leader) return action;
    const env::Route& route = *env.route();
    const Eigen::Vector2d position(result.ego.pose.x_m, result.ego.pose.y_m);
    s_m_ = route.project(position, s_m_, 20.0).s_m;
    const auto& others = env.traffic_boxes();
    estimate_velocities(others, env.config().ego.dt_s);
    const double ahead_m = options_.min_gap_m + options_.headway_s * result.ego.speed_mps;
    // Inside a junction with a car close behind, the ego is committed: coasting there lets
    // that car, which SUMO may no longer link to the turning ego, run into it.
    const bool committed = options_.clear_junction && env.events().road().in_junction &&
                           follower_behind(env.ego_box(), others, options_.follower_gap_m);
    const bool yield =
        leader_ahead(route, s_m_, others, ahead_m, options_.corridor_m) ||
        (!committed && conflict_ahead(route, env.ego_box(), s_m_, result.ego.speed_mps, others,
                                      velocities_, options_, yaw_rates_));
    previous_.assign(others.begin(), others.end());
    if (!yield) return action;
    // Keep the follower's steering, drop the throttle: coasting is the only brake there is.
    return env::encode_action(action / 3, 0);
  }

 private:
  // Velocity of each box from the nearest box of the previous step (boxes carry no ids; at
  // most 8.3 m/s, a car moves under 1 m per step, so the nearest within 2 m is the same car).
  void estimate_velocities(std::span<const env::Box> others, double dt_s) {
    velocities_.assign(others.size(), Eigen::Vector2d::Zero());
    yaw_rates_.assign(others.size(), 0.0);
    for (std::size_t i = 0; i < others.size(); ++i) {
      const Eigen::Vector2d now(others[i].pose.x_m, others[i].pose.y_m);
      double best = 2.0;
      for (const env::Box& before : previous_) {
        const Eigen::Vector2d then(before.pose.x_m, before.pose.y_m);
        const double distance = (now - then).norm();
        if (distance < best) {
          best = distance;
          velocities_[i] = (now - then) / dt_s;
          yaw_rates_[i] = env::wrap_angle(others[i].pose.yaw_rad - before.pose.yaw_rad) / dt_s;
        }
      }
    }
  }

  OracleOptions options_;
  std::optional<env::WaypointFollower> follower_;
  double s_m_ = 0.0;
  std::vector<env::Box> previous_;
  std::vector<Eigen::Vector2d> velocities_;
  std::vector<double> yaw_rates_;  // rad/s, counter-clockwise positive, one per box
};

class RandomPolicy final : public EpisodePolicy {
 public:
  explicit RandomPolicy(std::uint64_t seed) : seed_(seed) {}
  void begin(const env::Env&, const EpisodeSpec& spec) override {
    rng_.seed(seed_ * 0x9e3779b97f4a7c15ull + spec.policy_seed + 1);
  }
  int act(const env::Env&, const env::StepResult&) override { return pick_(rng_); }

 private:
  std::uint64_t seed_;
  std::mt19937_64 rng_;
  std::uniform_int_distribution<int> pick_{0, env::kNumActions - 1};
};

}  // namespace

PolicySource parse_policy_source(const std::string& text) {
  if (text == "snapshot") return PolicySource::kSnapshot;
  if (text == "oracle") return PolicySource::kOracle;
  if (text == "random") return PolicySource::kRandom;
  throw EvalError("unknown evaluation policy '" + text +
                  "'; use snapshot (a learner's or a file's), oracle (the route follower) or "
                  "random");
}

const char* to_string(PolicySource source) {
  switch (source) {
    case PolicySource::kSnapshot:
      return "snapshot";
    case PolicySource::kOracle:
      return "oracle";
    case PolicySource::kRandom:
      return "random";
  }
  return "snapshot";
}

agent::AgentConfig acting_config(agent::AgentConfig agent_config, PolicyHead head) {
  // The policy's acting actor follows the phase: pretrain acts with the exploration actor.
  if (head == PolicyHead::kExploration) {
    agent_config.phase = agent::Phase::kPretrain;
  } else if (agent_config.phase == agent::Phase::kPretrain) {
    agent_config.phase = agent::Phase::kFinetune;
  }
  return agent_config;
}

std::unique_ptr<EpisodePolicy> make_snapshot_policy(agent::AgentConfig agent_config,
                                                    std::span<const std::uint8_t> blob,
                                                    PolicyHead head, const std::string& source) {
  check_snapshot_head(blob, head, source);
  agent_config = acting_config(std::move(agent_config), head);
  try {
    return std::make_unique<SnapshotPolicy>(agent_config, blob);
  } catch (const std::exception& error) {
    throw EvalError(source + " does not fit the configured model (preset " + agent_config.preset +
                    "): " + error.what() + "; evaluate it with the preset it was trained with");
  }
}

std::unique_ptr<EpisodePolicy> make_oracle_policy(const OracleOptions& options) {
  return std::make_unique<OraclePolicy>(options);
}

bool leader_ahead(const env::Route& route, double ego_s_m, std::span<const env::Box> others,
                  double ahead_m, double corridor_m) {
  for (const env::Box& box : others) {
    const Eigen::Vector2d centre(box.pose.x_m, box.pose.y_m);
    const env::RoutePoint at = route.project(centre, ego_s_m, ahead_m + 5.0);
    double ds = at.s_m - ego_s_m;
    if (route.is_loop()) {
      ds = std::fmod(ds + route.length_m(), route.length_m());
      if (ds > 0.5 * route.length_m()) ds -= route.length_m();
    }
    if (ds > 0.0 && ds <= ahead_m && std::abs(at.lateral_m) <= corridor_m) return true;
  }
  return false;
}

bool conflict_ahead(const env::Route& route, const env::Box& ego, double ego_s_m,
                    double ego_speed_mps, std::span<const env::Box> others,
                    std::span<const Eigen::Vector2d> velocities, const OracleOptions& options,
                    std::span<const double> yaw_rates) {
  INDRIVE_CHECK_EQ(others.size(), velocities.size());
  INDRIVE_CHECK(yaw_rates.empty() || yaw_rates.size() == others.size())
      << yaw_rates.size() << " yaw rates for " << others.size() << " boxes";
  const double cos_yaw = std::cos(ego.pose.yaw_rad);
  const double sin_yaw = std::sin(ego.pose.yaw_rad);
  const double speed = std::max(ego_speed_mps, options.min_plan_speed_mps);
  constexpr double kSampleS = 0.2;
  for (std::size_t i = 0; i < others.size(); ++i) {
    const env::Box& other = others[i];
    // Behind the ego (in its frame): the other car's business, coasting would not help.
    const double forward =
        cos_yaw * (other.pose.x_m - ego.pose.x_m) + sin_yaw * (other.pose.y_m - ego.pose.y_m);
    if (forward < 0.0) continue;
    // Standing cars are the leader test's business; predicting them here only blocks the ego
    // beside cars that wait at a junction for it.
    const double other_speed = velocities[i].norm();
    if (other_speed < 0.5) continue;
    // A turning car keeps its turn rate until it has turned a right angle (the end of any
    // turn at a junction); a straight-line guess misses the car turning into the ego's road.
    const double rate = yaw_rates.empty() ? 0.0
                                          : std::clamp(yaw_rates[i], -options.max_yaw_rate_rps,
                                                       options.max_yaw_rate_rps);
    double heading = std::atan2(velocities[i].y(), velocities[i].x());
    double turned = 0.0;
    env::Box other_then = other;
    for (double t = 0.0; t <= options.horizon_s + 1e-9; t += kSampleS) {
      env::Box ego_then = ego;
      ego_then.pose = route.pose_at(ego_s_m + speed * t);
      ego_then.length_m += 2.0 * options.clearance_m;
      ego_then.width_m += 2.0 * options.clearance_m;
      if (env::boxes_overlap(ego_then, other_then)) return true;
      other_then.pose.x_m += other_speed * std::cos(heading) * kSampleS;
      other_then.pose.y_m += other_speed * std::sin(heading) * kSampleS;
      if (std::abs(turned) < 0.5 * std::numbers::pi) {
        heading += rate * kSampleS;
        turned += rate * kSampleS;
        other_then.pose.yaw_rad += rate * kSampleS;
      }
    }
  }
  return false;
}

bool follower_behind(const env::Box& ego, std::span<const env::Box> others, double gap_m) {
  const Eigen::Vector2d f(std::cos(ego.pose.yaw_rad), std::sin(ego.pose.yaw_rad));
  for (const env::Box& other : others) {
    const Eigen::Vector2d d(other.pose.x_m - ego.pose.x_m, other.pose.y_m - ego.pose.y_m);
    const double forward = f.dot(d);
    const double lateral = f.x() * d.y() - f.y() * d.x();
    // Behind, roughly in line (a turning ego's rear swings across the lane it came from).
    if (forward < 0.0 && -forward <= gap_m && std::abs(lateral) <= 0.5 * ego.width_m + 2.0) {
      return true;
    }
  }
  return false;
}

std::unique_ptr<EpisodePolicy> make_random_policy(std::uint64_t seed) {
  return std::make_unique<RandomPolicy>(seed);
}
}  // namespace indrive::actor
