// Tests of pacing.h: what the learner's allowance and heartbeat say, and that a change goes out
// without being forced.
#include "indrive/learner/pacing.h"

#include <gtest/gtest.h>

#include <chrono>
#include <mutex>
#include <thread>
#include <vector>

#include "testing.h"

namespace indrive::learner {
namespace {

using namespace std::chrono_literals;

// An actor's view of the pacing: every allowance and heartbeat it receives.
struct Listener {
  explicit Listener(const dds::ParticipantOptions& options) : endpoints(options) {
    allowance_reader = &endpoints.reader<msg::StepAllowance>([this](const msg::StepAllowance& a) {
      std::lock_guard<std::mutex> lock(mutex);
      allowances.push_back(a);
    });
    heartbeat_reader = &endpoints.reader<msg::Heartbeat>([this](const msg::Heartbeat& h) {
      std::lock_guard<std::mutex> lock(mutex);
      heartbeats.push_back(h);
    });
  }
  // Waits up to `timeout` until the newest allowance and heartbeat received say `allowed` and
  // `state`.
  bool wait_for(std::uint64_t allowed, const std::string& state,
                std::chrono::milliseconds timeout) {
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    while (true) {
      {
        std::lock_guard<std::mutex> lock(mutex);
        if (!allowances.empty() && allowances.back().total_env_steps() == allowed &&
            !heartbeats.empty() && heartbeats.back().state() == state) {
          return true;
        }
      }
      if (std::chrono::steady_clock::now() >= deadline) return false;
      std::this_thread::sleep_for(10ms);
    }
  }

  dds::EndpointSet endpoints;
  dds::Reader<msg::StepAllowance>* allowance_reader = nullptr;
  dds::Reader<msg::Heartbeat>* heartbeat_reader = nullptr;
  std::mutex mutex;
  std::vector<msg::StepAllowance> allowances;
  std::vector<msg::Heartbeat> heartbeats;
};

TEST(PacerTest, SaysTheAllowanceAndTheReceivedStepsAndSendsAChangeUnforced) {
  const dds::ParticipantOptions options{
      .domain_id = testing::unique_domain_id(),
      .profiles_file = testing::source_path("deploy/dds/single_host.xml").string()};
  dds::EndpointSet learner(options);
  Pacer pacer(learner, "run-pace");
  Listener actor(options);
  ASSERT_TRUE(actor.allowance_reader->wait_for_matched(1, 10s));
  ASSERT_TRUE(actor.heartbeat_reader->wait_for_matched(1, 10s));

  PacingState state{.allowed = 2048,
                    .env_steps = 1500,
                    .updates = 12,
                    .policy_version = 3,
                    .learner_epoch = 2,
                    .replay_ratio = 32.0,
                    .dropped_chunks = 1};
  // Forced, and again until it arrives: the learner's writers may match the actor's readers
  // after the actor's side matched, and what they wrote before that is lost (volatile topics).
  for (int i = 0; i < 300 && !actor.wait_for(2048, "running", 100ms); ++i) {
    EXPECT_TRUE(pacer.publish(state, /*force=*/true));
  }
  ASSERT_TRUE(actor.wait_for(2048, "running", 0ms));
  {
    std::lock_guard<std::mutex> lock(actor.mutex);
    const msg::StepAllowance& a = actor.allowances.back();
    EXPECT_EQ(dds::validate(a, "run-pace"), dds::DropReason::kOk);
    EXPECT_EQ(a.total_env_steps(), 2048u);
    EXPECT_EQ(a.replay_ratio(), 32.0);
    EXPECT_EQ(a.learner_epoch(), 2u);
    EXPECT_EQ(a.policy_version(), 3u);
    const msg::Heartbeat& h = actor.heartbeats.back();
    EXPECT_EQ(dds::validate(h, "run-pace"), dds::DropReason::kOk);
    EXPECT_EQ(h.role(), msg::ROLE_LEARNER);
    EXPECT_EQ(h.state(), "running");
    EXPECT_EQ(h.env_steps(), 1500u);
    EXPECT_EQ(h.updates(), 12u);
    EXPECT_EQ(h.policy_version(), 3u);
    EXPECT_EQ(h.dropped_messages(), 1u);
  }

  std::this_thread::sleep_for(10ms);  // more than the 5 ms between changes
  state.allowed = 4096;
  state.done = true;
  EXPECT_TRUE(pacer.publish(state, /*force=*/false)) << "a changed allowance goes out unforced";
  // (and again every 100 ms until it arrives, as the learner's loop does)
  for (int i = 0; i < 300 && !actor.wait_for(4096, "done", 100ms); ++i) pacer.publish(state, false);
  EXPECT_TRUE(actor.wait_for(4096, "done", 0ms));
}

}  // namespace
}  // namespace indrive::learner
