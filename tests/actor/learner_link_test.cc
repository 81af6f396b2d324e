// The link to the learner that training actors and evaluators share: what it hears, what it
// sends, and when it replaces its participant. Each test has a DDS domain of its own.
#include "indrive/actor/learner_link.h"

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <mutex>
#include <thread>
#include <vector>

#include "indrive/dds/security.h"
#include "testing.h"

namespace indrive::actor {
namespace {

using Clock = std::chrono::steady_clock;
using std::chrono::milliseconds;

// A run "link-test" (the run id is the run directory's name) on a domain of its own.
service::ServiceConfig resolve(const std::filesystem::path& dir) {
  return service::ServiceConfig::resolve({.run_dir = dir / "link-test",
                                          .domain_id = testing::unique_domain_id(),
                                          .overrides = {"preset=tiny"}});
}

LearnerLinkOptions evaluator_options(double rejoin_after_s, double rejoin_max_s) {
  return {.role = "evaluator",
          .requester_role = msg::ROLE_EVALUATOR,
          .id = 3,
          .architecture = "test-architecture",
          .request_after_s = 2.0,
          .rejoin_after_s = rejoin_after_s,
          .rejoin_max_s = rejoin_max_s};
}

// Polls `done` every 10 ms for up to 30 s (discovery between participants of one process).
template <typename Predicate>
bool eventually(Predicate done) {
  const auto deadline = Clock::now() + std::chrono::seconds(30);
  while (!done()) {
    if (Clock::now() > deadline) return false;
    std::this_thread::sleep_for(milliseconds(10));
  }
  return true;
}

// A stand-in learner: its heartbeats, and the snapshot requests it hears.
struct StandInLearner {
  explicit StandInLearner(const service::ServiceConfig& config)
      : config(config), endpoints(config.participant_options("learner")) {
    heartbeats = &endpoints.writer<msg::Heartbeat>();
    endpoints.reader<msg::SnapshotRequest>([this](const msg::SnapshotRequest& request) {
      std::lock_guard<std::mutex> lock(mutex);
      requests.push_back(request);
    });
  }
  void beat(const std::string& state, std::uint64_t version, const std::string& run_id,
            msg::Role role = msg::ROLE_LEARNER) {
    msg::Heartbeat heartbeat;
    heartbeat.role(role);
    heartbeat.run_id(run_id);
    heartbeat.state(state);
    heartbeat.policy_version(version);
    dds::seal(heartbeat);
    heartbeats->write(heartbeat);
  }
  std::size_t request_count() {
    std::lock_guard<std::mutex> lock(mutex);
    return requests.size();
  }

  const service::ServiceConfig& config;
  dds::EndpointSet endpoints;
  dds::Writer<msg::Heartbeat>* heartbeats = nullptr;
  std::mutex mutex;
  std::vector<msg::SnapshotRequest> requests;
};

TEST(LearnerLinkTest, HearsOnlyItsOwnLearnerAndItsLastVersionAndSendsRequestsAsItsRole) {
  testing::TempDir dir;
  const auto config = resolve(dir.path());
  std::atomic<int> heartbeats_seen{0};
  std::atomic<int> endpoint_sets{0};
  LearnerLink link(config, evaluator_options(0.0, 0.0),
                   {.add_endpoints = [&](dds::EndpointSet&, LearnerLink&) { ++endpoint_sets; },
                    .on_heartbeat = [&](const msg::Heartbeat&) { ++heartbeats_seen; }});
  EXPECT_EQ(endpoint_sets.load(), 1);
  EXPECT_EQ(link.heard_at(), Clock::time_point{}) << "nothing heard yet";
  StandInLearner learner(config);

  // Another run's learner and this run's actors reach the hook, but are not the learner.
  ASSERT_TRUE(eventually([&] {
    learner.beat("running", 1, "another-run");
    learner.beat("running", 1, "link-test", msg::ROLE_ACTOR);
    return heartbeats_seen.load() >= 2;
  }));
  EXPECT_EQ(link.heard_at(), Clock::time_point{});
  EXPECT_EQ(link.final_version(), 0u);

  ASSERT_TRUE(eventually([&] {
    learner.beat("running", 4, "link-test");
    return link.heard_at() != Clock::time_point{};
  }));
  EXPECT_LT(link.silent_s(), 30.0);
  EXPECT_EQ(link.final_version(), 0u) << "a running learner has named no last version";
  ASSERT_TRUE(eventually([&] {
    learner.beat("done", 7, "link-test");
    return link.final_version() == 7u;
  }));

  ASSERT_TRUE(eventually([&] {
    link.request_snapshot();
    return learner.request_count() > 0;
  }));
  std::lock_guard<std::mutex> lock(learner.mutex);
  const msg::SnapshotRequest& request = learner.requests.front();
  EXPECT_EQ(request.run_id(), "link-test");
  EXPECT_EQ(request.requester_role(), msg::ROLE_EVALUATOR);
  EXPECT_EQ(request.requester_id(), 3u);
  EXPECT_EQ(dds::validate(request, "link-test"), dds::DropReason::kOk);
}

// With no learner to hear, the participant is replaced after the wait, and each replacement that
// heard nothing doubles the next wait up to the maximum; each new participant gets the owner's
// endpoints again.
TEST(LearnerLinkTest, ASilentLinkIsReplacedAfterWaitsThatDoubleUpToTheMaximum) {
  testing::TempDir dir;
  const auto config = resolve(dir.path());
  std::atomic<int> endpoint_sets{0};
  LearnerLink link(config, evaluator_options(1.0, 2.0),
                   {.add_endpoints = [&](dds::EndpointSet&, LearnerLink&) { ++endpoint_sets; }});
  const dds::EndpointSet* first = &link.endpoints();
  EXPECT_FALSE(link.maybe_rejoin()) << "the participant is new";
  std::this_thread::sleep_for(milliseconds(1100));
  EXPECT_TRUE(link.maybe_rejoin());
  EXPECT_EQ(link.rejoins(), 1u);
  EXPECT_EQ(endpoint_sets.load(), 2);
  EXPECT_NE(&link.endpoints(), first);
  std::this_thread::sleep_for(milliseconds(1100));
  EXPECT_FALSE(link.maybe_rejoin()) << "the second wait is 2 s";
  std::this_thread::sleep_for(milliseconds(1000));
  EXPECT_TRUE(link.maybe_rejoin());
  EXPECT_EQ(link.rejoins(), 2u);
}

// A link that has heard its learner is not replaced when the learner falls silent, unless it is
// a training actor's (replace_silent_over_shm) over shared memory; never with rejoin off.
TEST(LearnerLinkTest, AHeardLearnersSilenceReplacesOnlyAnActorsSharedMemoryParticipant) {
  testing::TempDir dir;
  const auto config = resolve(dir.path());
  LearnerLinkOptions actor_options = evaluator_options(1.0, 1.0);
  actor_options.role = "actor";
  actor_options.requester_role = msg::ROLE_ACTOR;
  actor_options.replace_silent_over_shm = true;
  LearnerLink evaluator(config, evaluator_options(1.0, 1.0));
  LearnerLink actor(config, actor_options);
  LearnerLink never(config, evaluator_options(0.0, 0.0));
  {
    StandInLearner learner(config);
    ASSERT_TRUE(eventually([&] {
      learner.beat("running", 1, "link-test");
      return evaluator.heard_at() != Clock::time_point{} &&
             actor.heard_at() != Clock::time_point{} && never.heard_at() != Clock::time_point{};
    }));
  }
  std::this_thread::sleep_for(milliseconds(1100));
  EXPECT_GE(evaluator.silent_s(), 1.0);
  EXPECT_FALSE(evaluator.maybe_rejoin());
  EXPECT_FALSE(never.maybe_rejoin());
  const bool shared_memory = actor.endpoints().participant().uses_shared_memory();
  EXPECT_EQ(actor.maybe_rejoin(), shared_memory);
  // heard() from the owner (an actor's allowance) counts as hearing the learner.
  evaluator.heard();
  EXPECT_LT(evaluator.silent_s(), 1.0);
}

}  // namespace
}  // namespace indrive::actor
