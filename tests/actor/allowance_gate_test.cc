#include "indrive/actor/allowance_gate.h"

#include <gtest/gtest.h>

#include <chrono>
#include <thread>

namespace indrive::actor {
namespace {

using std::chrono::milliseconds;
using std::chrono::seconds;

msg::StepAllowance allowance(std::uint64_t total, const std::string& run = "run-a",
                             std::uint64_t epoch = 1) {
  msg::StepAllowance a;
  a.run_id(run);
  a.total_env_steps(total);
  a.replay_ratio(32.0);
  a.learner_epoch(epoch);
  dds::seal(a);
  return a;
}

msg::Heartbeat learner_heartbeat(std::uint64_t received, const std::string& run = "run-a",
                                 msg::Role role = msg::ROLE_LEARNER) {
  msg::Heartbeat h;
  h.run_id(run);
  h.role(role);
  h.env_steps(received);
  dds::seal(h);
  return h;
}

TEST(AllowanceGateTest, StepsUpToTheAllowanceCountingOwnStepsSinceTheHeartbeat) {
  AllowanceGate gate("run-a");
  EXPECT_FALSE(gate.may_step(0)) << "no step before the learner has paced the run";
  gate.on_allowance(allowance(100));
  EXPECT_FALSE(gate.may_step(0)) << "how much of the allowance is spent comes with a heartbeat";
  gate.on_learner_heartbeat(learner_heartbeat(0), 0);
  EXPECT_TRUE(gate.may_step(0));
  EXPECT_TRUE(gate.may_step(99));
  EXPECT_FALSE(gate.may_step(100));
  // The learner has received 90 steps when this actor had taken 95: 5 are in flight, so the
  // estimate at 104 own steps is 90 + 9 = 99 (one more allowed) and 100 at 105.
  gate.on_learner_heartbeat(learner_heartbeat(90), 95);
  EXPECT_TRUE(gate.may_step(104));
  EXPECT_FALSE(gate.may_step(105));
}

// An actor that joins a resumed learner (or replaces one mid-run) starts with 0 steps of its
// own while the learner has received many: it waits for the heartbeat that says how many, not
// stepping up to the whole allowance alone (a service job resumed under Slurm overshot its
// 1,100-step budget by 900 steps that way).
TEST(AllowanceGateTest, AJoiningActorWaitsForTheLearnersCountOfWhatItReceived) {
  AllowanceGate gate("run-a");
  gate.on_allowance(allowance(1100, "run-a", 2));
  EXPECT_FALSE(gate.may_step(0));
  gate.on_learner_heartbeat(learner_heartbeat(1090), 0);
  EXPECT_TRUE(gate.may_step(9));
  EXPECT_FALSE(gate.may_step(10));
}

TEST(AllowanceGateTest, ForeignAndNonLearnerMessagesNeitherPaceNorWake) {
  AllowanceGate gate("run-a");
  gate.on_allowance(allowance(100, "run-b"));
  gate.on_learner_heartbeat(learner_heartbeat(0, "run-b"), 0);
  gate.on_learner_heartbeat(learner_heartbeat(0, "run-a", msg::ROLE_ACTOR), 0);
  EXPECT_FALSE(gate.may_step(0));
  EXPECT_EQ(gate.news(), 0u);
  EXPECT_FALSE(gate.wait_for_news(0, milliseconds(1))) << "nothing arrived: the wait times out";
}

TEST(AllowanceGateTest, EveryAcceptedMessageAndWakeCountsAsNews) {
  AllowanceGate gate("run-a");
  gate.on_allowance(allowance(10));
  gate.on_learner_heartbeat(learner_heartbeat(5), 5);
  gate.wake();
  EXPECT_EQ(gate.news(), 3u);
  EXPECT_TRUE(gate.wait_for_news(2, seconds(0))) << "news after `seen` ends the wait at once";
}

// A waiting actor is woken by the allowance's arrival, not by the end of its wait: the wait
// here is an hour long, so this test would hang (and fail by its timeout) if the callback did
// not wake it.
TEST(AllowanceGateTest, AnAllowanceArrivingOnAnotherThreadWakesTheWaiter) {
  AllowanceGate gate("run-a");
  gate.on_learner_heartbeat(learner_heartbeat(0), 0);
  const std::uint64_t seen = gate.news();
  ASSERT_FALSE(gate.may_step(0));
  std::thread learner([&] {
    std::this_thread::sleep_for(milliseconds(20));
    gate.on_allowance(allowance(64));
  });
  EXPECT_TRUE(gate.wait_for_news(seen, std::chrono::hours(1)));
  EXPECT_TRUE(gate.may_step(0));
  learner.join();
}

TEST(AllowanceGateTest, ASnapshotsWakeEndsTheWaitWithoutPacing) {
  AllowanceGate gate("run-a");
  const std::uint64_t seen = gate.news();
  std::thread inbox([&] {
    std::this_thread::sleep_for(milliseconds(20));
    gate.wake();
  });
  EXPECT_TRUE(gate.wait_for_news(seen, std::chrono::hours(1)));
  EXPECT_FALSE(gate.may_step(0)) << "a wake is news, not an allowance";
  inbox.join();
}

// The actor counts an accepted message as word of the learner (learner_link.h): only the
// learner's own, of this run, are accepted.
TEST(AllowanceGateTest, SaysWhichMessagesItAccepted) {
  AllowanceGate gate("run-a");
  EXPECT_TRUE(gate.on_allowance(allowance(100)));
  EXPECT_FALSE(gate.on_allowance(allowance(100, "run-b")));
  EXPECT_TRUE(gate.on_learner_heartbeat(learner_heartbeat(0), 0));
  EXPECT_FALSE(gate.on_learner_heartbeat(learner_heartbeat(0, "run-b"), 0));
  EXPECT_FALSE(gate.on_learner_heartbeat(learner_heartbeat(0, "run-a", msg::ROLE_ACTOR), 0));
  msg::StepAllowance other_schema = allowance(100);
  other_schema.schema_version(other_schema.schema_version() + 1);
  EXPECT_FALSE(gate.on_allowance(other_schema));
}

}  // namespace
}  // namespace indrive::actor
