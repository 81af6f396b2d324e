// Tests of snapshot_publisher.h: versions reserved on disk before they leave the process, and
// the snapshot written, kept, written again on request and announced.
#include "indrive/learner/snapshot_publisher.h"

#include <fastrtps/attributes/LibrarySettingsAttributes.h>
#include <fastrtps/xmlparser/XMLProfileManager.h>
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <mutex>
#include <thread>
#include <vector>

#include "indrive/agent/agent.h"
#include "indrive/agent/snapshot_file.h"
#include "indrive/basics/run_dir.h"
#include "indrive/learner/checkpoint.h"
#include "testing.h"

namespace indrive::learner {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;

std::string text_of(const fs::path& path) {
  const auto bytes = read_file(path);
  return {bytes.begin(), bytes.end()};
}

TEST(VersionReservationTest, ReservesABlockAheadAndReleasesDownToThePublishedVersion) {
  testing::TempDir dir;
  const fs::path file = dir.path() / "policy_versions_reserved";
  VersionReservation versions(file);
  EXPECT_EQ(versions.reserved(), 0u) << "no file: nothing reserved";
  versions.reserve(1);
  EXPECT_EQ(versions.reserved(), 100u);
  EXPECT_EQ(text_of(file), "100");
  versions.reserve(57);  // inside the block: no write needed
  EXPECT_EQ(versions.reserved(), 100u);
  versions.reserve(101);
  EXPECT_EQ(versions.reserved(), 200u);
  EXPECT_EQ(VersionReservation(file).reserved(), 200u) << "a restart reads the mark back";
  versions.release(103);
  EXPECT_EQ(versions.reserved(), 103u);
  EXPECT_EQ(VersionReservation(file).reserved(), 103u);

  std::ofstream(file) << "not a number";
  EXPECT_THROW(VersionReservation{file}, CheckpointError);
}

TEST(SnapshotPublisherTest, PublishesKeepsRepublishesAndAnnounces) {
  const dds::ParticipantOptions options{
      .domain_id = testing::unique_domain_id(),
      .profiles_file = testing::source_path("deploy/dds/single_host.xml").string()};
  dds::EndpointSet learner(options);
  SnapshotPublisher publisher(learner, "run-p", /*hold_s=*/10.0);
  EXPECT_TRUE(publisher.ready()) << "the first snapshot waits for nothing";
  EXPECT_FALSE(publisher.newest());
  EXPECT_FALSE(publisher.republish(false)) << "nothing to write before the first snapshot";

  dds::EndpointSet actor(options);
  std::mutex mutex;
  std::vector<std::uint64_t> snapshots, announced;
  std::vector<bool> done_flags;
  auto& snapshot_reader = actor.reader<msg::PolicySnapshot>([&](const msg::PolicySnapshot& s) {
    std::lock_guard<std::mutex> lock(mutex);
    if (dds::validate(s, "run-p") == dds::DropReason::kOk) snapshots.push_back(s.version());
  });
  auto& announce_reader = actor.reader<msg::SnapshotAnnounce>([&](const msg::SnapshotAnnounce& a) {
    std::lock_guard<std::mutex> lock(mutex);
    announced.push_back(a.version());
    done_flags.push_back(a.learner_done());
  });
  auto& requests = actor.writer<msg::SnapshotRequest>();
  ASSERT_TRUE(requests.wait_for_matched(1, 10s));
  ASSERT_TRUE(snapshot_reader.wait_for_matched(1, 10s));
  ASSERT_TRUE(announce_reader.wait_for_matched(1, 10s));
  // The actor's side matching is not enough: the learner's writers may discover the actor's
  // readers later, and a volatile announce written before that is lost (about 1 run in 10
  // failed so, with every announce missing and the snapshot seen once).
  const int readers_at_first_match = publisher.readers();
  for (int i = 0; i < 1000 && publisher.readers() < 1; ++i) std::this_thread::sleep_for(10ms);
  ASSERT_EQ(publisher.readers(), 1) << "the learner's writers never matched the actor's readers";

  msg::PolicySnapshot snapshot;
  snapshot.version(3);
  snapshot.architecture("image=8");
  snapshot.heads(msg::HEAD_ENCODER);
  snapshot.params(std::vector<std::uint8_t>(64, 7));
  publisher.publish(snapshot, /*done=*/false);
  ASSERT_TRUE(publisher.newest());
  EXPECT_EQ(publisher.newest()->run_id(), "run-p") << "the publisher names its run";

  msg::SnapshotRequest request;
  request.run_id("run-p");
  dds::seal(request);
  requests.write(request);
  for (int i = 0; i < 500 && !publisher.request_pending(); ++i) std::this_thread::sleep_for(10ms);
  ASSERT_TRUE(publisher.request_pending());
  // Written again only once the reader has the first write: a second write would replace the
  // first under a reader still fetching it.
  ASSERT_TRUE(publisher.wait_until_delivered(10s));
  EXPECT_TRUE(publisher.delivered());
  EXPECT_TRUE(publisher.ready()) << "delivered: the next snapshot may go";
  EXPECT_TRUE(publisher.serve_request(/*done=*/true));
  EXPECT_FALSE(publisher.request_pending());
  EXPECT_FALSE(publisher.serve_request(/*done=*/true)) << "one write per request";
  publisher.announce_final(/*done=*/true);

  // Announces are "keep last": a reader may see only the newest of quick ones, which must be
  // the final one.
  // Up to 30 s: a reliable resend after a lost first packet waits for the writer's next
  // heartbeat (on a loaded CI host both once took longer than the 5 s this allowed).
  for (int i = 0; i < 3000; ++i) {
    {
      std::lock_guard<std::mutex> lock(mutex);
      if (snapshots.size() >= 2 && !done_flags.empty() && done_flags.back()) break;
    }
    std::this_thread::sleep_for(10ms);
  }
  std::lock_guard<std::mutex> lock(mutex);
  std::printf("[ figures  ] readers matched by the learner when the actor matched: %d\n",
              readers_at_first_match);
  EXPECT_EQ(snapshots, (std::vector<std::uint64_t>{3, 3})) << "published, then again on request";
  ASSERT_FALSE(announced.empty());
  for (const std::uint64_t version : announced) EXPECT_EQ(version, 3u);
  EXPECT_TRUE(done_flags.back()) << "the final announce says the run is done";
}

// A publisher and an actor whose snapshot reader holds the first snapshot in its callback, so
// its participant acknowledges nothing until the test lets go; intraprocess delivery is off, or
// the write would run that callback on the writer's thread.
struct HeldReader {
  HeldReader(const std::string& run_id, double hold_s)
      : options(single_host_options()),
        learner(options),
        publisher(learner, run_id, hold_s),
        actor(options) {
    snapshot_reader = &actor.reader<msg::PolicySnapshot>([this](const msg::PolicySnapshot&) {
      ++received;
      while (!let_go.load()) std::this_thread::sleep_for(1ms);
    });
    actor.reader<msg::SnapshotAnnounce>([](const msg::SnapshotAnnounce&) {});
  }
  ~HeldReader() { let_go = true; }

  static dds::ParticipantOptions single_host_options() {
    eprosima::fastrtps::LibrarySettingsAttributes library;
    library.intraprocess_delivery = eprosima::fastrtps::INTRAPROCESS_OFF;
    eprosima::fastrtps::xmlparser::XMLProfileManager::library_settings(library);
    return {.domain_id = testing::unique_domain_id(),
            .profiles_file = testing::source_path("deploy/dds/single_host.xml").string()};
  }
  // Waits until the learner's writers match the reader.
  bool matched() {
    if (!snapshot_reader->wait_for_matched(1, 10s)) return false;
    for (int i = 0; i < 1000 && publisher.readers() < 1; ++i) std::this_thread::sleep_for(10ms);
    return publisher.readers() >= 1;
  }
  // Publishes `version` and waits until the reader holds it.
  bool publish_and_hold(std::uint64_t version) {
    msg::PolicySnapshot snapshot;
    snapshot.version(version);
    snapshot.architecture("image=8");
    snapshot.heads(msg::HEAD_ENCODER);
    snapshot.params(std::vector<std::uint8_t>(64, 9));
    publisher.publish(snapshot, /*done=*/false);
    for (int i = 0; i < 1000 && received.load() == 0; ++i) std::this_thread::sleep_for(10ms);
    return received.load() == 1;
  }

  dds::ParticipantOptions options;
  dds::EndpointSet learner;
  SnapshotPublisher publisher;
  dds::EndpointSet actor;
  dds::Reader<msg::PolicySnapshot>* snapshot_reader = nullptr;
  std::atomic<int> received{0};
  std::atomic<bool> let_go{false};
};

// A late joiner's request that arrives while the last snapshot is still on its way to another
// reader cannot be served at once (a second write would start that reader over): it is kept
// and served as soon as the write is acknowledged, not dropped.
TEST(SnapshotPublisherTest, ARequestWhileTheLastWriteIsUnacknowledgedIsServedOnceItIs) {
  HeldReader rig("run-q", /*hold_s=*/60.0);
  SnapshotPublisher& publisher = rig.publisher;
  dds::EndpointSet asker(rig.options);
  auto& requests = asker.writer<msg::SnapshotRequest>();
  ASSERT_TRUE(rig.matched());
  ASSERT_TRUE(requests.wait_for_matched(1, 10s));

  EXPECT_FALSE(publisher.serve_request(false)) << "no request yet";
  ASSERT_TRUE(rig.publish_and_hold(5));
  ASSERT_FALSE(publisher.ready()) << "the held reader acknowledged the first write";

  msg::SnapshotRequest request;
  request.run_id("run-q");
  dds::seal(request);
  requests.write(request);
  for (int i = 0; i < 500 && !publisher.request_pending(); ++i) std::this_thread::sleep_for(10ms);
  ASSERT_TRUE(publisher.request_pending());
  EXPECT_FALSE(publisher.serve_request(false)) << "the last write is still on its way";
  EXPECT_TRUE(publisher.request_pending()) << "the request is kept, not dropped";

  rig.let_go = true;
  ASSERT_TRUE(publisher.wait_until_delivered(10s));
  EXPECT_TRUE(publisher.serve_request(false));
  EXPECT_FALSE(publisher.request_pending());
  for (int i = 0; i < 1000 && rig.received.load() < 2; ++i) std::this_thread::sleep_for(10ms);
  EXPECT_EQ(rig.received.load(), 2) << "the snapshot written again for the request";
}

// A due snapshot waits while a reader lacks the last one, counted once as held however often
// the learner asks, and goes once the reader has it.
TEST(SnapshotPublisherTest, ADueSnapshotIsHeldUntilTheReaderHasTheLastOne) {
  HeldReader rig("run-h", /*hold_s=*/60.0);
  SnapshotPublisher& publisher = rig.publisher;
  ASSERT_TRUE(rig.matched());
  EXPECT_FALSE(publisher.take_due(0)) << "nothing is due";
  publisher.mark_due();
  EXPECT_TRUE(publisher.take_due(10)) << "the first snapshot waits for nothing";
  EXPECT_FALSE(publisher.due());
  ASSERT_TRUE(rig.publish_and_hold(1));

  publisher.mark_due();
  EXPECT_FALSE(publisher.take_due(20));
  EXPECT_FALSE(publisher.take_due(21));
  EXPECT_TRUE(publisher.due()) << "held, still due";
  EXPECT_EQ(publisher.holds(), 1u);
  rig.let_go = true;
  ASSERT_TRUE(publisher.wait_until_delivered(10s));
  EXPECT_TRUE(publisher.take_due(22));
  EXPECT_FALSE(publisher.due());
  EXPECT_EQ(publisher.holds(), 1u);
  EXPECT_EQ(publisher.holds_expired(), 0u);
}

// A reader that never acknowledges holds the next snapshot for hold_s, no longer; the hold that
// ran out is counted. A snapshot published directly (the run's last) is no longer due.
TEST(SnapshotPublisherTest, AHoldRunsOutAfterHoldSeconds) {
  HeldReader rig("run-x", /*hold_s=*/0.5);
  SnapshotPublisher& publisher = rig.publisher;
  ASSERT_TRUE(rig.matched());
  ASSERT_TRUE(rig.publish_and_hold(1));
  publisher.mark_due();
  EXPECT_FALSE(publisher.take_due(5));
  std::this_thread::sleep_for(600ms);
  EXPECT_TRUE(publisher.take_due(6));
  EXPECT_EQ(publisher.holds(), 1u);
  EXPECT_EQ(publisher.holds_expired(), 1u);

  publisher.mark_due();
  msg::PolicySnapshot last = *publisher.newest();
  last.version(2);
  publisher.publish(last, /*done=*/true);
  EXPECT_FALSE(publisher.due());
}

// The final snapshot file holds the newest snapshot with its provenance; none before the first.
TEST(SnapshotPublisherTest, TheFinalFileHoldsTheNewestSnapshotAndItsProvenance) {
  testing::TempDir dir;
  const dds::ParticipantOptions options{
      .domain_id = testing::unique_domain_id(),
      .profiles_file = testing::source_path("deploy/dds/single_host.xml").string()};
  dds::EndpointSet learner(options);
  SnapshotPublisher publisher(learner, "run-f", /*hold_s=*/10.0);
  agent::AgentConfig agent_config = agent::preset("tiny");
  const fs::path file = dir.path() / "final-snapshot.params";
  publisher.write_final_file(file, agent_config);
  EXPECT_FALSE(fs::exists(file)) << "no snapshot yet";

  const std::vector<std::uint8_t> params = agent::Agent(agent_config).snapshot();
  msg::PolicySnapshot snapshot;
  snapshot.version(9);
  snapshot.env_steps(1234);
  snapshot.params(params);
  publisher.publish(snapshot, /*done=*/true);
  publisher.write_final_file(file, agent_config);
  const agent::SnapshotFile read = agent::read_snapshot_file(file);
  EXPECT_EQ(read.blob, params);
  ASSERT_TRUE(read.provenance());
  EXPECT_EQ(read.provenance()->run_id, "run-f");
  EXPECT_EQ(read.provenance()->version, 9u);
  EXPECT_EQ(read.provenance()->env_steps, 1234u);

  publisher.write_final_file(dir.path() / "no-such-dir" / "x.params", agent_config);  // logged
}

}  // namespace
}  // namespace indrive::learner
