#include "indrive/dds/messages.h"

#include <fastdds/rtps/common/SerializedPayload.h>
#include <gtest/gtest.h>

#include <thread>

#include "synthetic_traffic.h"

namespace indrive::dds {
namespace {

using testing::make_synthetic_chunk;
using testing::make_synthetic_snapshot;

TEST(DdsMessages, SealedChunkValidates) {
  const auto chunk = make_synthetic_chunk("run-a", 3, 17);
  EXPECT_EQ(chunk.schema_version(), kSchemaVersion);
  EXPECT_EQ(validate(chunk, "run-a"), DropReason::kOk);
  EXPECT_EQ(validate(chunk, ""), DropReason::kOk) << "an empty run id accepts every run";
  EXPECT_EQ(testing::compare_with_synthetic(chunk), "");
}

TEST(DdsMessages, EachCorruptionHasItsReason) {
  const auto good = make_synthetic_chunk("run-a", 0, 5);

  auto flipped = good;
  flipped.frames_zstd()[flipped.frames_zstd().size() / 2] ^= 1;
  EXPECT_EQ(validate(flipped, "run-a"), DropReason::kBadChecksum);

  auto header_changed = good;  // header fields are covered by the checksum too
  header_changed.chunk_seq(header_changed.chunk_seq() + 1);
  EXPECT_EQ(validate(header_changed, "run-a"), DropReason::kBadChecksum);

  auto event_changed = good;
  event_changed.events()[3] ^= 0x100;
  EXPECT_EQ(validate(event_changed, "run-a"), DropReason::kBadChecksum);

  auto newer_schema = good;
  newer_schema.schema_version(kSchemaVersion + 1);
  newer_schema.frames_zstd()[0] ^= 1;  // schema is judged before anything else
  EXPECT_EQ(validate(newer_schema, "run-a"), DropReason::kWrongSchema);

  EXPECT_EQ(validate(good, "run-b"), DropReason::kWrongRun);

  auto short_actions = good;
  short_actions.actions().pop_back();
  seal(short_actions);
  EXPECT_EQ(validate(short_actions, "run-a"), DropReason::kBadShape);

  auto wrong_rewards = good;
  wrong_rewards.rewards(std::vector<float>(3, 0.5f));
  seal(wrong_rewards);
  EXPECT_EQ(validate(wrong_rewards, "run-a"), DropReason::kBadShape);

  auto full_rewards = good;
  full_rewards.rewards(std::vector<float>(good.num_steps(), 0.5f));
  seal(full_rewards);
  EXPECT_EQ(validate(full_rewards, "run-a"), DropReason::kOk) << "rewards: empty or one per step";

  auto small_frames = good;  // frames that decode to fewer bytes than L * H * W
  small_frames.frames_zstd(compress_frames(std::vector<std::uint8_t>(1000, 7)));
  seal(small_frames);
  EXPECT_EQ(validate(small_frames, "run-a"), DropReason::kBadShape);

  auto not_zstd = good;
  not_zstd.frames_zstd(std::vector<std::uint8_t>(100, 0xab));
  seal(not_zstd);
  EXPECT_EQ(validate(not_zstd, "run-a"), DropReason::kBadShape);
}

TEST(DdsMessages, SnapshotChecksumCoversParamsAndDescriptor) {
  const auto good = make_synthetic_snapshot("run-a", 4, 1 << 16);
  EXPECT_EQ(validate(good, "run-a"), DropReason::kOk);

  auto flipped = good;
  flipped.params()[12345] ^= 0x80;
  EXPECT_EQ(validate(flipped, "run-a"), DropReason::kBadChecksum);

  auto other_architecture = good;
  other_architecture.architecture("image=64");
  EXPECT_EQ(validate(other_architecture, "run-a"), DropReason::kBadChecksum);

  auto empty = good;
  empty.params().clear();
  seal(empty);
  EXPECT_EQ(validate(empty, "run-a"), DropReason::kBadShape);
  EXPECT_EQ(validate(good, "run-z"), DropReason::kWrongRun);
}

TEST(DdsMessages, AnnounceDescribesItsSnapshot) {
  const auto snapshot = make_synthetic_snapshot("run-a", 9, 4096);
  const auto announce = announce_for(snapshot);
  EXPECT_EQ(validate(announce, "run-a"), DropReason::kOk);
  EXPECT_EQ(announce.version(), 9u);
  EXPECT_EQ(announce.checksum(), snapshot.checksum());
  EXPECT_EQ(announce.size_bytes(), 4096u);
}

// A results row on the wire and back: every shared field arrives (the float fields at float
// precision), the sender's and reader's own fields are left to them.
TEST(DdsMessages, EpisodeFieldsRoundTripThroughAnEpisodeResult) {
  const EpisodeRecord row{.run_id = "lf-s1",
                          .method = "disag",
                          .eval_kind = "training",
                          .task = "lane_following",
                          .train_seed = 1,
                          .policy_version = 4096,
                          .town = "town01",
                          .route = "left_loop",
                          .density = 20,
                          .traffic_seed = 987654,
                          .spawn_seed = 123456,
                          .episode = 7,
                          .success = false,
                          .failure_reason = "off_route",
                          .steps = 812,
                          .route_completion = 0.25,
                          .episode_return = -12.5};
  msg::EpisodeResult result;
  set_episode_fields(result, row);
  EXPECT_EQ(result.sender_role(), msg::EpisodeResult().sender_role());
  const EpisodeRecord back = episode_fields(result);
  EXPECT_EQ(back.run_id, "lf-s1");
  EXPECT_EQ(back.policy_version, 4096);
  EXPECT_EQ(back.town, "town01");
  EXPECT_EQ(back.route, "left_loop");
  EXPECT_EQ(back.density, 20);
  EXPECT_EQ(back.traffic_seed, 987654);
  EXPECT_EQ(back.spawn_seed, 123456);
  EXPECT_FALSE(back.success);
  EXPECT_EQ(back.failure_reason, "off_route");
  EXPECT_EQ(back.steps, 812);
  EXPECT_DOUBLE_EQ(back.route_completion, 0.25);
  EXPECT_DOUBLE_EQ(back.episode_return, -12.5);
  EXPECT_EQ(back.method, "");
  EXPECT_EQ(back.eval_kind, "");
  EXPECT_EQ(back.episode, 0);
}

TEST(DdsMessages, SmallMessagesCheckHeaderAndRanges) {
  msg::EpisodeResult result;
  result.run_id("r");
  result.route_completion(0.75f);
  seal(result);
  EXPECT_EQ(validate(result, "r"), DropReason::kOk);
  result.route_completion(1.5f);
  EXPECT_EQ(validate(result, "r"), DropReason::kBadShape);

  msg::Heartbeat heartbeat;  // unsealed: schema 0
  heartbeat.run_id("r");
  EXPECT_EQ(validate(heartbeat, "r"), DropReason::kWrongSchema);
  seal(heartbeat);
  EXPECT_EQ(validate(heartbeat, "q"), DropReason::kWrongRun);

  msg::StepAllowance allowance;
  allowance.run_id("r");
  allowance.replay_ratio(std::numeric_limits<double>::quiet_NaN());
  seal(allowance);
  EXPECT_EQ(validate(allowance, "r"), DropReason::kBadShape);
}

TEST(DdsMessages, FramesCompressLosslesslyAndWell) {
  const auto frames = testing::synthetic_frames(3, 64, 128, 128);
  const auto compressed = compress_frames(frames);
  EXPECT_EQ(decompress_frames(compressed, frames.size()), frames);
  // Segmentation frames are mostly constant regions: expect at least 10x.
  EXPECT_LT(compressed.size() * 10, frames.size()) << "ratio " << frames.size() / compressed.size();
}

TEST(DdsMessages, CorruptFramesThrowDataError) {
  const auto frames = testing::synthetic_frames(1, 8, 32, 32);
  auto compressed = compress_frames(frames);
  EXPECT_THROW(decompress_frames(compressed, frames.size() + 1), DataError);
  EXPECT_THROW(decompress_frames(std::vector<std::uint8_t>(64, 0x11), frames.size()), DataError);
  compressed[compressed.size() / 2] ^= 0xff;
  compressed[compressed.size() / 2 + 1] ^= 0xff;
  // Either zstd notices (its frame checksum is off by default) or the bytes differ: never
  // silently the original.
  try {
    EXPECT_NE(decompress_frames(compressed, frames.size()), frames);
  } catch (const DataError&) {
  }
}

TEST(DdsMessages, ChunkSurvivesCdrSerialization) {
  const auto chunk = make_synthetic_chunk("run-a", 1, 2);
  msg::TrajectoryChunkPubSubType type;
  eprosima::fastrtps::rtps::SerializedPayload_t payload(
      type.getSerializedSizeProvider(const_cast<msg::TrajectoryChunk*>(&chunk))());
  ASSERT_TRUE(type.serialize(const_cast<msg::TrajectoryChunk*>(&chunk), &payload));
  msg::TrajectoryChunk decoded;
  ASSERT_TRUE(type.deserialize(&payload, &decoded));
  EXPECT_EQ(decoded, chunk);
  EXPECT_EQ(validate(decoded, "run-a"), DropReason::kOk);
}

// The generated type lets fastcdr's BadParamException out of deserialize (it would end a
// subscriber inside DataReader::take); the registered type drops the sample and counts it.
TEST(DdsMessages, UndecodableSamplesAreDroppedAndCountedNotThrown) {
  const auto chunk = make_synthetic_chunk("run-a", 1, 2);
  TopicTraits<msg::TrajectoryChunk>::PubSubType type;
  eprosima::fastrtps::rtps::SerializedPayload_t payload(
      type.getSerializedSizeProvider(const_cast<msg::TrajectoryChunk*>(&chunk))());
  ASSERT_TRUE(type.serialize(const_cast<msg::TrajectoryChunk*>(&chunk), &payload));
  payload.data[0] = 0x7f;  // no CDR encapsulation starts with this byte
  msg::TrajectoryChunk decoded;
  msg::TrajectoryChunkPubSubType generated;
  EXPECT_THROW(generated.deserialize(&payload, &decoded), eprosima::fastcdr::exception::Exception);
  const std::uint64_t before = undecodable_samples();
  EXPECT_FALSE(type.deserialize(&payload, &decoded));
  payload.length = 3;  // cut short: the generated type's own `false`, counted too
  payload.data[0] = 0;
  EXPECT_FALSE(type.deserialize(&payload, &decoded));
  EXPECT_EQ(undecodable_samples(), before + 2);
}

TEST(DdsMessages, DropCountersAreExactUnderConcurrency) {
  DropCounters counters;
  std::vector<std::thread> threads;
  for (int t = 0; t < 4; ++t) {
    threads.emplace_back([&counters, t] {
      for (int i = 0; i < 12000; ++i) counters.record(static_cast<DropReason>((i + t) % 6));
    });
  }
  for (auto& thread : threads) thread.join();
  for (int r = 0; r < kNumDropReasons; ++r) {
    EXPECT_EQ(counters.count(static_cast<DropReason>(r)), 8000u);
  }
  EXPECT_EQ(counters.dropped(), 40000u);
  EXPECT_EQ(counters.summary(),
            "accepted=8000 wrong_schema=8000 wrong_run=8000 bad_shape=8000 bad_checksum=8000 "
            "duplicate=8000");
}

}  // namespace
}  // namespace indrive::dds
