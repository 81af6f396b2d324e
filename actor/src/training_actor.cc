#include "indrive/actor/training_actor.h"

#include <chrono>
#include <mutex>
#include <random>
#include <thread>

#include "indrive/actor/actor_config.h"
#include "indrive/actor/allowance_gate.h"
#include "indrive/actor/chunk_builder.h"
#include "indrive/actor/env_adapter.h"
#include "indrive/actor/eval_protocol_record.h"
#include "indrive/actor/learner_link.h"
#include "indrive/agent/policy.h"
#include "indrive/basics/check.h"
#include "indrive/basics/log.h"
#include "indrive/basics/stopwatch.h"
#include "indrive/dds/participant.h"
#include "indrive/dds/security.h"
#include "indrive/envserver/coverage.h"
#include "indrive/nn/nn.h"

namespace indrive::actor {
namespace {

using Clock = std::chrono::steady_clock;

double unix_time_s() {
  return std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
}

}  // namespace

struct TrainingActor::Impl {
  Impl(const service::ServiceConfig& service, std::uint32_t actor_id)
      : config(service),
        id(actor_id),
        agent_config(service.agent()),
        env_config(actor::env_config(service)),
        settings(actor_config(service.config())),
        chunk_length(settings.chunk_length),
        heartbeat_period_s(settings.heartbeat_s),
        with_rewards(agent_config.phase != agent::Phase::kPretrain),
        gate(service.run_id()),
        builder({.run_id = service.run_id(),
                 .actor_id = actor_id,
                 .height = agent_config.world_model.image,
                 .width = agent_config.world_model.image,
                 .chunk_length = chunk_length,
                 .phase = service.wire_phase(),
                 .with_rewards = with_rewards}),
        policy(agent_config),
        random_policy(agent_config.seed * 1000003u + actor_id),
        rng(agent_config.seed * 7919u + actor_id + 1) {
    // DDS first: a learner can see this actor while SUMO is still loading.
    connect();
    heartbeat("starting");

    const EnvAdapterOptions episodes = EnvAdapter::options_from(service);
    densities = episodes.densities;
    density_period = episodes.density_period_steps;
    routes = route_list(episodes.route);
    env = std::make_unique<env::Env>(env_config);
    coverage = std::make_unique<env::CoverageTracker>(
        env->town().net, env::CoverageOptions{.segment_m = episodes.coverage_segment_m});
    coverage_period_s = settings.coverage_period_s;
    INDRIVE_LOG(kInfo, "actor") << "actor " << id << " of run '" << service.run_id()
                                << "' ready: town " << env_config.town << ", image "
                                << agent_config.world_model.image << ", architecture '"
                                << service::architecture_descriptor(agent_config) << "'";
  }

  // The link's readers call into the gate and the counters: it goes first.
  ~Impl() { link.reset(); }

  // This actor's link to the learner: its snapshots and requests, episode results and the
  // participant's replacement (learner_link.h); the actor adds its chunks, heartbeats and the
  // learner's allowances. The state they feed (snapshot inbox, allowance gate) lives outside the
  // participant, so a new one carries on where the old one stopped.
  void connect() {
    link = std::make_unique<LearnerLink>(
        config,
        LearnerLinkOptions{.role = "actor",
                           .requester_role = msg::ROLE_ACTOR,
                           .id = id,
                           .architecture = service::architecture_descriptor(agent_config),
                           .request_after_s = settings.request_after_s,
                           .rejoin_after_s = settings.rejoin_after_s,
                           .rejoin_max_s = settings.rejoin_max_s,
                           .replace_silent_over_shm = true},
        LearnerLinkHooks{.add_endpoints =
                             [this](dds::EndpointSet& set, LearnerLink& self) {
                               chunk_writer = &set.writer<msg::TrajectoryChunk>();
                               heartbeat_writer = &set.writer<msg::Heartbeat>();
                               set.reader<msg::StepAllowance>(
                                   [this, &self](const msg::StepAllowance& a) {
                                     if (gate.on_allowance(a)) self.heard();
                                   });
                             },
                         .on_snapshot_news = [this] { gate.wake(); },
                         .on_heartbeat =
                             [this](const msg::Heartbeat& heartbeat) {
                               gate.on_learner_heartbeat(heartbeat, own_steps.load());
                             }});
  }

  // Called only where this actor waits for the learner (learner_link.h says when it replaces
  // the participant); a new participant says at once who this actor is.
  void maybe_rejoin() {
    if (!link->maybe_rejoin()) return;
    stats.rejoins = link->rejoins();
    heartbeat("waiting");
  }

  void heartbeat(const char* state) {
    msg::Heartbeat beat;
    beat.role(msg::ROLE_ACTOR);
    beat.id(id);
    beat.run_id(config.run_id());
    beat.state(state);
    beat.policy_version(stats.policy_version);
    beat.env_steps(stats.env_steps);
    beat.dropped_messages(link->inbox().drops().dropped() + link->inbox().architecture_rejects());
    beat.wall_time_s(unix_time_s());
    dds::seal(beat);
    heartbeat_writer->write(beat);
    last_heartbeat = Clock::now();
  }

  void maybe_heartbeat(const char* state) {
    if (seconds_since(last_heartbeat) >= heartbeat_period_s) heartbeat(state);
  }

  // Writes a chunk, retrying while the learner's history is full (back-pressure).
  void publish(const msg::TrajectoryChunk& chunk, const std::atomic<bool>& stop) {
    const auto start = Clock::now();
    while (!chunk_writer->write(chunk)) {
      if (stop.load()) return;
      INDRIVE_LOG(kDebug, "actor") << "chunk writer blocked; retrying";
      maybe_heartbeat("blocked");
      maybe_rejoin();
    }
    ++stats.chunks;
    stats.publish_s += seconds_since(start);
  }

  // Loads a newer snapshot if one arrived; the open chunk is sent first so that every chunk
  // is made by one policy version.
  void maybe_swap(const std::atomic<bool>& stop) {
    auto snapshot = link->inbox().take_newer_than(stats.policy_version);
    if (snapshot == nullptr) return;
    if (!builder.empty() && builder.policy_version() != snapshot->version()) {
      publish(builder.take(), stop);
    }
    const auto start = Clock::now();
    try {
      policy.load_snapshot(snapshot->params());
    } catch (const std::exception& error) {
      ++stats.snapshots_rejected;
      INDRIVE_LOG(kError, "actor")
          << "rejected snapshot v" << snapshot->version() << ": " << error.what();
      stats.policy_version = snapshot->version();  // do not retry the same bytes
      return;
    }
    const bool first = !have_policy;
    have_policy = true;
    restart_state = true;
    stats.policy_version = snapshot->version();
    ++stats.snapshots_loaded;
    heartbeat("running");  // announces the version in use at once (publish-to-use latency)
    INDRIVE_LOG_AT(first ? log::Level::kInfo : log::Level::kDebug, "actor")
        << "acting with snapshot v" << snapshot->version() << " (" << snapshot->params().size()
        << " bytes, loaded in " << seconds_since(start) * 1000.0 << " ms)";
  }

  void maybe_request() {
    if (!link->inbox().should_request(stats.policy_version, Clock::now())) return;
    link->request_snapshot();
    ++stats.snapshot_requests;
    INDRIVE_LOG(kInfo, "actor") << "announced snapshot v" << link->inbox().announced_version()
                                << " not received; requested it again";
  }

  // Blocks while the allowance is used up, keeping heartbeats and snapshot swaps going. It
  // sleeps until the learner's next allowance or heartbeat, or a snapshot, arrives (their DDS
  // callbacks wake it), and at least every kWaitTick for the timed duties (heartbeat, rejoin,
  // snapshot request). It used to poll every 2 ms: in a rate-limited run on 2 cores the actor
  // waits about 94% of the time, and each of those 500 wake-ups a second took a core from the
  // learner's threads in the middle of an update (docs/performance.md).
  void wait_for_allowance(const std::atomic<bool>& stop) {
    if (gate.may_step(own_steps.load())) return;
    constexpr auto kWaitTick = std::chrono::milliseconds(50);
    const auto start = Clock::now();
    while (!stop.load()) {
      const std::uint64_t seen = gate.news();  // news from here on cut the wait short
      if (gate.may_step(own_steps.load())) break;
      maybe_heartbeat("waiting");
      maybe_rejoin();
      maybe_request();
      maybe_swap(stop);
      if (gate.may_step(own_steps.load())) break;
      gate.wait_for_news(seen, kWaitTick);
    }
    stats.wait_s += seconds_since(start);
  }

  int choose_action(const env::StepResult& result) {
    if (result.is_last) return 0;  // no action follows the last frame
    if (!have_policy) return random_policy.act();
    const cv::Mat& frame = result.observation;
    const bool first = result.is_first || restart_state;
    restart_state = false;
    return policy.act(std::span<const std::uint8_t>(frame.data, frame.total()), first, policy_state,
                      /*sample=*/true);
  }

  void publish_result(const env::StepResult& last, double episode_return, int reach) {
    msg::EpisodeResult result;
    const env::Route* driven = env->route();
    EpisodeRecord record =
        training_record({.town = env_config.town,
                         .route = route,
                         .density = density,
                         .traffic_seed = static_cast<int>(traffic_seed),
                         .spawn_seed = static_cast<int>(spawn_seed),
                         .route_length_m = driven == nullptr ? 0.0 : driven->length_m(),
                         .episode_return = episode_return},
                        last);
    record.run_id = config.run_id();
    record.policy_version = static_cast<long long>(stats.policy_version);
    dds::set_episode_fields(result, record);
    result.sender_role(msg::ROLE_ACTOR);
    result.sender_id(id);
    result.phase(config.wire_phase());
    result.reach_segments(static_cast<std::uint32_t>(reach));
    dds::seal(result);
    link->results().write(result);
  }

  void run(const std::atomic<bool>& stop) {
    const auto start = Clock::now();
    std::uint64_t episode_id = 0;
    std::int64_t next_density_draw = 0;
    const int pixels = agent_config.world_model.image * agent_config.world_model.image;
    while (!stop.load()) {
      // Episode choices: density redrawn every density_period steps, fresh seeds per episode.
      if (static_cast<std::int64_t>(stats.env_steps) >= next_density_draw) {
        density = static_cast<int>(densities[rng() % densities.size()]);
        next_density_draw += density_period;
      }
      traffic_seed = rng() % 1000000u;
      spawn_seed = rng() % 1000000u;
      route = draw_route(routes, rng);
      env::StepResult result = env->reset({.route = route,
                                           .density = density,
                                           .traffic_seed = traffic_seed,
                                           .spawn_seed = spawn_seed});
      policy_state = agent::PolicyState{};
      double episode_return = 0.0;
      while (!stop.load()) {
        maybe_swap(stop);
        wait_for_allowance(stop);
        if (stop.load()) break;
        const int action = choose_action(result);
        INDRIVE_CHECK_EQ(result.observation.total(), static_cast<std::size_t>(pixels))
            << "the camera must render the preset's image size";
        std::optional<float> reward;
        if (with_rewards) reward = static_cast<float>(result.reward.value_or(0.0));
        const bool complete =
            builder.add({.frame = {result.observation.data, static_cast<std::size_t>(pixels)},
                         .action = action,
                         .is_first = result.is_first,
                         .is_last = result.is_last,
                         .is_terminal = result.is_terminal,
                         .events = result.events,
                         .reward = reward,
                         .episode_id = episode_id,
                         .episode_step = static_cast<std::uint64_t>(result.step),
                         .policy_version = stats.policy_version});
        ++stats.env_steps;
        own_steps.store(stats.env_steps);
        coverage->observe(result.ego.pose);
        if (seconds_since(last_coverage_write) >= coverage_period_s) write_coverage();
        episode_return += reward.value_or(0.0f);
        if (complete) publish(builder.take(), stop);
        maybe_heartbeat("running");
        maybe_request();
        if (result.is_last) {
          coverage->end_episode();  // has this episode's steps: observed just above
          publish_result(result, episode_return, coverage->episode_reach().back());
          ++stats.episodes;
          break;
        }
        result = env->step(action);
      }
      ++episode_id;
      // A stopped episode's open chunk is dropped: the learner never gets a partial chunk.
    }
    write_coverage();
    heartbeat("stopping");
    // The chunks written just before the stop reach the learner before the participant goes:
    // a writer deleted with samples in flight may take them along. (Once, in CI, the learner
    // stored one chunk fewer than the fault test's own reader had received; this may be why.)
    if (chunk_writer != nullptr &&
        !chunk_writer->wait_for_acknowledgments(std::chrono::seconds(2))) {
      INDRIVE_LOG(kWarn, "actor") << "the learner did not acknowledge this actor's last chunks "
                                     "within 2 s of the stop; they may be lost";
    }
    stats.total_s = seconds_since(start);
    INDRIVE_LOG(kInfo, "actor") << "actor " << id << " stops: " << stats.env_steps << " steps, "
                                << stats.chunks << " chunks, " << stats.episodes
                                << " episodes, policy v" << stats.policy_version << ", "
                                << stats.rejoins << " rejoins, waited " << stats.wait_s << " s of "
                                << stats.total_s << " s, publishing took " << stats.publish_s
                                << " s";
  }

  // Writes coverage/actor-<id>.csv of the run atomically; a failure is logged, never fatal:
  // coverage is a measurement, not part of training.
  void write_coverage() {
    last_coverage_write = Clock::now();
    try {
      coverage->write_csv(config.run_dir() / "coverage" / ("actor-" + std::to_string(id) + ".csv"));
    } catch (const std::exception& error) {
      INDRIVE_LOG(kWarn, "actor") << "cannot write coverage: " << error.what();
    }
  }

  const service::ServiceConfig& config;
  std::uint32_t id;
  agent::AgentConfig agent_config;
  env::EnvConfig env_config;
  const ActorConfig settings;  // the actor.* keys, read once
  int chunk_length;
  double heartbeat_period_s;
  bool with_rewards;
  AllowanceGate gate;
  ChunkBuilder builder;
  agent::Policy policy;
  agent::RandomPolicy random_policy;
  std::mt19937_64 rng;
  // The link to the learner; the writers below belong to its current participant.
  std::unique_ptr<LearnerLink> link;
  dds::Writer<msg::TrajectoryChunk>* chunk_writer = nullptr;
  dds::Writer<msg::Heartbeat>* heartbeat_writer = nullptr;
  std::unique_ptr<env::Env> env;
  std::unique_ptr<env::CoverageTracker> coverage;
  double coverage_period_s = 60.0;
  Clock::time_point last_coverage_write = Clock::now();
  std::vector<double> densities;
  std::int64_t density_period = 10000;
  std::vector<std::string> routes;  // env.route as a list (empty: random spawns)
  std::string route;                // the current episode's
  int density = 10;
  std::uint64_t traffic_seed = 0;
  std::uint64_t spawn_seed = 0;
  agent::PolicyState policy_state;
  bool have_policy = false;
  bool restart_state = false;
  std::atomic<std::uint64_t> own_steps{0};
  Clock::time_point last_heartbeat{};
  ActorStats stats;
};

TrainingActor::TrainingActor(const service::ServiceConfig& config, std::uint32_t id)
    : impl_(std::make_unique<Impl>(config, id)) {}
TrainingActor::~TrainingActor() = default;
void TrainingActor::run(const std::atomic<bool>& stop) { impl_->run(stop); }
const ActorStats& TrainingActor::stats() const { return impl_->stats; }

}  // namespace indrive::actor
