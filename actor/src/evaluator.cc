#include "indrive/actor/evaluator.h"

#include <chrono>
#include <sstream>
#include <stdexcept>
#include <thread>

#include "indrive/actor/snapshot_inbox.h"
#include "indrive/common/agent/policy.h"
#include "indrive/common/dds.h"
#include "indrive/common/episode_csv.h"
#include "indrive/common/log.h"
#include "indrive/common/run_dir.h"

namespace indrive::actor {
namespace {

using Clock = std::chrono::steady_clock;

std::vector<std::string> split_list(const std::string& text) {
  std::vector<std::string> items;
  std::stringstream stream(text);
  std::string item;
  while (std::getline(stream, item, ',')) {
    const auto begin = item.find_first_not_of(' ');
    const auto end = item.find_last_not_of(' ');
    if (begin != std::string::npos) items.push_back(item.substr(begin, end - begin + 1));
  }
  return items;
}

}  // namespace

ProtocolGrid protocol_grid(const config::Config& config) {
  ProtocolGrid grid;
  grid.towns = split_list(config.get<std::string>("eval.towns"));
  grid.routes = split_list(config.get<std::string>("eval.routes"));
  grid.densities.clear();
  for (double density : config.get<std::vector<double>>("eval.densities")) {
    grid.densities.push_back(static_cast<int>(density));
  }
  grid.episodes_per_cell = config.get<int>("eval.episodes_per_cell");
  grid.validate();
  return grid;
}

struct Evaluator::Impl {
  Impl(const ServiceConfig& service, int evaluator_index, int evaluator_count)
      : config(service),
        index(evaluator_index),
        count(evaluator_count),
        agent_config(service.agent()),
        grid(protocol_grid(service.config())),
        inbox(service.run_id(), architecture_descriptor(agent_config),
              service.config().get<double>("actor.request_after_s")),
        policy(agent_config) {
    participant = std::make_unique<dds::Participant>(dds::ParticipantOptions{
        .domain_id = service.domain_id(), .profiles_file = service.dds_profile()});
    result_writer = participant->make_writer<msg::EpisodeResult>();
    request_writer = participant->make_writer<msg::SnapshotRequest>();
    policy_reader = participant->make_reader<msg::PolicySnapshot>(
        [this](const msg::PolicySnapshot& snapshot) { inbox.offer(snapshot); });
    announce_reader = participant->make_reader<msg::SnapshotAnnounce>(
        [this](const msg::SnapshotAnnounce& announce) { inbox.announce(announce); });
    heartbeat_reader =
        participant->make_reader<msg::Heartbeat>([this](const msg::Heartbeat& heartbeat) {
          if (heartbeat.role() == msg::ROLE_LEARNER && heartbeat.state() == "done" &&
              dds::validate(heartbeat, config.run_id()) == dds::DropReason::kOk) {
            learner_done.store(heartbeat.policy_version());
          }
        });
    env::EnvConfig env_config = service.env();
    env_config.town = grid.towns.front();
    env = std::make_unique<env::Env>(env_config);
  }

  ~Impl() {
    policy_reader.reset();
    announce_reader.reset();
    heartbeat_reader.reset();
    result_writer.reset();
    request_writer.reset();
    participant.reset();
  }

  // The snapshot to evaluate: the newest one, or the learner's final one when asked to wait.
  std::shared_ptr<const msg::PolicySnapshot> wait_for_snapshot(const std::atomic<bool>& stop) {
    const bool wait_for_done = config.config().get<bool>("eval.wait_for_done");
    const double timeout_s = config.config().get<double>("eval.snapshot_timeout_s");
    const auto start = Clock::now();
    while (!stop.load() &&
           std::chrono::duration<double>(Clock::now() - start).count() < timeout_s) {
      auto snapshot = inbox.take_newer_than(0);
      const std::uint64_t final_version = learner_done.load();
      if (snapshot != nullptr &&
          (!wait_for_done || (final_version > 0 && snapshot->version() >= final_version))) {
        return snapshot;
      }
      if (inbox.should_request(snapshot ? snapshot->version() : 0, Clock::now())) {
        msg::SnapshotRequest request;
        request.run_id(config.run_id());
        request.requester_role(msg::ROLE_EVALUATOR);
        request.requester_id(static_cast<std::uint32_t>(index));
        dds::seal(request);
        request_writer->write(request);
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    return nullptr;
  }

  int run(const std::atomic<bool>& stop) {
    const auto start = Clock::now();
    auto snapshot = wait_for_snapshot(stop);
    if (snapshot == nullptr) {
      if (stop.load()) return 0;
      INDRIVE_LOG(kError, "evaluator")
          << "no policy snapshot arrived within "
          << config.config().get<double>("eval.snapshot_timeout_s") << " s; is the learner of run '"
          << config.run_id() << "' running on domain " << config.domain_id() << "?";
      return 2;
    }
    policy.load_snapshot(snapshot->params());
    INDRIVE_LOG(kInfo, "evaluator")
        << "evaluator " << index << "/" << count << " evaluates snapshot v" << snapshot->version()
        << ", received " << std::chrono::duration<double>(Clock::now() - start).count()
        << " s after start";

    const auto episodes = grid.episodes_for(index, count);
    std::filesystem::create_directories(config.run_dir() / "eval");
    EpisodeCsvWriter csv(config.run_dir() / "eval" /
                         ("evaluator-" + std::to_string(index) + ".csv"));
    const agent::AgentConfig& a = agent_config;
    const std::string method = a.phase == agent::Phase::kDreamer
                                   ? "dreamer"
                                   : std::string(agent::to_string(a.intrinsic.method));
    const std::string task =
        a.phase == agent::Phase::kPretrain ? "exploration" : std::string(a.task);
    int done = 0;
    for (const EpisodeSpec& spec : episodes) {
      if (stop.load()) break;
      env::StepResult step =
          env->reset({.town = spec.town,
                      .route = spec.route,
                      .density = spec.density,
                      .traffic_seed = static_cast<std::uint64_t>(spec.traffic_seed),
                      .spawn_seed = static_cast<std::uint64_t>(spec.spawn_seed)});
      agent::PolicyState state;
      double episode_return = 0.0;
      while (!step.is_last && !stop.load()) {
        const int action = policy.act_eval(
            std::span<const std::uint8_t>(step.observation.data, step.observation.total()),
            step.is_first, state);
        step = env->step(action);
        episode_return += step.reward.value_or(0.0);
      }
      if (!step.is_last) break;
      const std::uint32_t failures = step.events & env::kFailureEvents;
      const env::Route* route = env->route();
      EpisodeRecord record;
      record.run_id = config.run_id();
      record.method = method;
      record.eval_kind = config.config().get<std::string>("eval.kind");
      record.task = task;
      record.train_seed = static_cast<int>(config.config().get<std::int64_t>("run.seed"));
      record.policy_version = static_cast<long long>(snapshot->version());
      record.town = spec.town;
      record.route = spec.route;
      record.density = spec.density;
      record.traffic_seed = spec.traffic_seed;
      record.spawn_seed = spec.spawn_seed;
      record.episode = spec.episode;
      record.success = (step.events & env::kDestination) != 0 && failures == 0;
      record.failure_reason = record.success ? "" : env::event_names(failures);
      record.steps = step.step;
      record.route_completion = route == nullptr || route->length_m() <= 0.0
                                    ? 0.0
                                    : std::min(1.0, step.route_progress_m / route->length_m());
      record.episode_return = episode_return;
      csv.write(record);

      msg::EpisodeResult result;
      result.run_id(config.run_id());
      result.sender_role(msg::ROLE_EVALUATOR);
      result.sender_id(static_cast<std::uint32_t>(index));
      result.phase(msg::PHASE_EVALUATION);
      result.policy_version(snapshot->version());
      result.town(spec.town);
      result.route(spec.route);
      result.density(static_cast<std::uint32_t>(spec.density));
      result.traffic_seed(static_cast<std::uint32_t>(spec.traffic_seed));
      result.spawn_seed(static_cast<std::uint32_t>(spec.spawn_seed));
      result.success(record.success);
      result.failure_reason(record.failure_reason);
      result.steps(static_cast<std::uint32_t>(record.steps));
      result.route_completion(static_cast<float>(record.route_completion));
      result.episode_return(static_cast<float>(episode_return));
      dds::seal(result);
      result_writer->write(result);
      ++done;
    }
    INDRIVE_LOG(kInfo, "evaluator")
        << "evaluator " << index << " ran " << done << " of " << episodes.size() << " episodes";
    result_writer->wait_for_acknowledgments(std::chrono::seconds(2));
    return 0;
  }

  const ServiceConfig& config;
  int index;
  int count;
  agent::AgentConfig agent_config;
  ProtocolGrid grid;
  SnapshotInbox inbox;
  agent::Policy policy;
  std::atomic<std::uint64_t> learner_done{0};
  std::unique_ptr<dds::Participant> participant;
  std::unique_ptr<dds::Writer<msg::EpisodeResult>> result_writer;
  std::unique_ptr<dds::Writer<msg::SnapshotRequest>> request_writer;
  std::unique_ptr<dds::Reader<msg::PolicySnapshot>> policy_reader;
  std::unique_ptr<dds::Reader<msg::SnapshotAnnounce>> announce_reader;
  std::unique_ptr<dds::Reader<msg::Heartbeat>> heartbeat_reader;
  std::unique_ptr<env::Env> env;
};

Evaluator::Evaluator(const ServiceConfig& config, int index, int count)
    : impl_(std::make_unique<Impl>(config, index, count)) {}
Evaluator::~Evaluator() = default;
int Evaluator::run(const std::atomic<bool>& stop) { return impl_->run(stop); }

}  // namespace indrive::actor
