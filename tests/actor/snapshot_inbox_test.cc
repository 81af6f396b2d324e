#include "indrive/actor/snapshot_inbox.h"

#include <gtest/gtest.h>

#include <chrono>
#include <thread>

namespace indrive::actor {
namespace {

msg::PolicySnapshot snapshot(std::uint64_t version, const std::string& run = "run-a",
                             const std::string& architecture = "arch-1") {
  msg::PolicySnapshot s;
  s.run_id(run);
  s.version(version);
  s.preset("tiny");
  s.architecture(architecture);
  s.heads(msg::HEAD_ENCODER | msg::HEAD_RSSM | msg::HEAD_EXPLORATION_ACTOR);
  s.params(std::vector<std::uint8_t>(100, static_cast<std::uint8_t>(version)));
  dds::seal(s);
  return s;
}

msg::SnapshotAnnounce announce(std::uint64_t version, bool learner_done = false,
                               const std::string& run = "run-a") {
  msg::SnapshotAnnounce a;
  a.run_id(run);
  a.learner_done(learner_done);
  a.version(version);
  a.checksum(1);
  a.size_bytes(100);
  dds::seal(a);
  return a;
}

TEST(SnapshotInboxTest, KeepsTheNewestValidSnapshot) {
  SnapshotInbox inbox("run-a", "arch-1", 1.0);
  EXPECT_EQ(inbox.take_newer_than(0), nullptr);
  EXPECT_TRUE(inbox.offer(snapshot(2)));
  EXPECT_FALSE(inbox.offer(snapshot(1))) << "an older version never replaces a newer one";
  auto held = inbox.take_newer_than(0);
  ASSERT_NE(held, nullptr);
  EXPECT_EQ(held->version(), 2u);
  EXPECT_EQ(inbox.take_newer_than(2), nullptr);
}

TEST(SnapshotInboxTest, ForeignCorruptAndMismatchedSnapshotsAreCountedNotKept) {
  SnapshotInbox inbox("run-a", "arch-1", 1.0);
  EXPECT_FALSE(inbox.offer(snapshot(5, "run-b")));
  auto corrupt = snapshot(6);
  corrupt.params()[10] ^= 0xff;
  EXPECT_FALSE(inbox.offer(corrupt));
  EXPECT_FALSE(inbox.offer(snapshot(7, "run-a", "arch-2")));
  EXPECT_EQ(inbox.drops().count(dds::DropReason::kWrongRun), 1u);
  EXPECT_EQ(inbox.drops().count(dds::DropReason::kBadChecksum), 1u);
  EXPECT_EQ(inbox.architecture_rejects(), 1u);
  EXPECT_EQ(inbox.take_newer_than(0), nullptr);
  EXPECT_TRUE(inbox.offer(snapshot(3))) << "a good snapshot still gets through afterwards";
}

TEST(SnapshotInboxTest, ReRequestsAnAnnouncedSnapshotThatDidNotArrive) {
  SnapshotInbox inbox("run-a", "arch-1", /*request_after_s=*/0.5);
  const auto t0 = SnapshotInbox::Clock::now();
  EXPECT_FALSE(inbox.should_request(0, t0)) << "nothing announced yet";
  inbox.announce(announce(4));
  const auto announced = SnapshotInbox::Clock::now();
  EXPECT_FALSE(inbox.should_request(0, announced)) << "give the snapshot time to arrive";
  const auto later = announced + std::chrono::seconds(1);
  EXPECT_TRUE(inbox.should_request(0, later));
  EXPECT_FALSE(inbox.should_request(0, later + std::chrono::milliseconds(100)))
      << "requests are spaced";
  EXPECT_TRUE(inbox.should_request(0, later + std::chrono::seconds(1)));
  inbox.offer(snapshot(4));
  EXPECT_FALSE(inbox.should_request(0, later + std::chrono::seconds(5))) << "it arrived";
  EXPECT_FALSE(inbox.should_request(4, later + std::chrono::seconds(5)));
}

// A learner that announces a newer version more often than request_after_s (a fast learner,
// a snapshot that takes longer than that to cross a slow link) must not put the request off:
// the wait counts from the first version announced beyond the one held.
TEST(SnapshotInboxTest, AnnouncesFasterThanTheWaitDoNotPutTheRequestOff) {
  SnapshotInbox inbox("run-a", "arch-1", /*request_after_s=*/0.5);
  const auto first = SnapshotInbox::Clock::now();
  inbox.announce(announce(4));
  for (std::uint64_t version = 5; version <= 7; ++version) {
    std::this_thread::sleep_for(std::chrono::milliseconds(250));
    inbox.announce(announce(version));
  }
  const auto now = SnapshotInbox::Clock::now();
  ASSERT_GE(now - first, std::chrono::milliseconds(500));
  EXPECT_TRUE(inbox.should_request(0, now)) << "v4 was announced over 0.5 s ago and is missing";

  // A snapshot that arrives restarts the wait for the newer ones.
  inbox.offer(snapshot(5));
  const auto arrived = SnapshotInbox::Clock::now();
  inbox.announce(announce(8));
  EXPECT_FALSE(inbox.should_request(5, arrived + std::chrono::milliseconds(100)));
  EXPECT_TRUE(inbox.should_request(5, arrived + std::chrono::seconds(1)));
}

TEST(SnapshotInboxTest, TheLearnersFinalAnnounceNamesTheLastVersion) {
  SnapshotInbox inbox("run-a", "arch-1", 1.0);
  inbox.announce(announce(3));
  EXPECT_EQ(inbox.final_version(), 0u) << "a periodic announce is not the last";
  inbox.announce(announce(5, true, "run-b"));
  EXPECT_EQ(inbox.final_version(), 0u) << "another run's final announce is ignored";
  inbox.announce(announce(4, true));
  EXPECT_EQ(inbox.final_version(), 4u);
  EXPECT_EQ(inbox.announced_version(), 4u);
}

}  // namespace
}  // namespace indrive::actor
