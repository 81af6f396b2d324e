#include "indrive/learner/learner.h"

#include <gtest/gtest.h>
#include <zstd.h>

#include <cstdio>
#include <functional>
#include <limits>
#include <nlohmann/json.hpp>

#include "indrive/basics/checksum.h"

namespace indrive::learner {
namespace {

constexpr std::size_t kTrailerSize = 15;   // "CRC32 " + 8 hex digits + "\n"
constexpr std::size_t kVersionDigit = 27;  // in "INDRIVE-LEARNER-CHECKPOINT 3\n"

std::vector<std::uint8_t> bytes_of(const std::string& text) { return {text.begin(), text.end()}; }

// Rewrites the trailer of a version 3 checkpoint for its (edited) content, as a file damaged in
// a way the checksum cannot see would look: what is left must then catch the damage.
std::vector<std::uint8_t> reseal(std::vector<std::uint8_t> bytes) {
  bytes.resize(bytes.size() - kTrailerSize);
  char trailer[kTrailerSize + 1];
  std::snprintf(trailer, sizeof trailer, "CRC32 %08x\n", crc32(bytes));
  bytes.insert(bytes.end(), trailer, trailer + kTrailerSize);
  return bytes;
}

// The same checkpoint in format version 2: the same layout without the trailer.
std::vector<std::uint8_t> as_version_2(std::vector<std::uint8_t> bytes) {
  EXPECT_EQ(bytes[kVersionDigit], '3');
  bytes[kVersionDigit] = '2';
  bytes.resize(bytes.size() - kTrailerSize);
  return bytes;
}

// A version 3 checkpoint with `edit` applied to its counters line, trailer recomputed.
std::vector<std::uint8_t> with_counters_line(const std::vector<std::uint8_t>& packed,
                                             const std::function<void(nlohmann::json&)>& edit) {
  const std::string text(packed.begin(), packed.end());
  const std::size_t begin = text.find('\n') + 1, end = text.find('\n', begin);
  nlohmann::json meta = nlohmann::json::parse(text.substr(begin, end - begin));
  edit(meta);
  return reseal(bytes_of(text.substr(0, begin) + meta.dump() + text.substr(end)));
}

std::string unpack_error(std::span<const std::uint8_t> bytes) {
  std::vector<std::uint8_t> agent_out, replay_out;
  try {
    unpack_checkpoint(bytes, agent_out, &replay_out);
  } catch (const CheckpointError& error) {
    return error.what();
  }
  return "(no error)";
}

TEST(LearnerCheckpointTest, PackedCountersAndAgentBytesRoundTrip) {
  const LearnerCounters counters{
      .env_steps = 12345, .updates = 678, .policy_version = 9, .learner_epoch = 2};
  const std::vector<std::uint8_t> agent_bytes = {0, 1, 2, '\n', 255, 7};
  const auto packed = pack_checkpoint(counters, agent_bytes);
  std::vector<std::uint8_t> restored_bytes;
  const LearnerCounters restored = unpack_checkpoint(packed, restored_bytes);
  EXPECT_EQ(restored.env_steps, 12345);
  EXPECT_EQ(restored.updates, 678);
  EXPECT_EQ(restored.policy_version, 9u);
  EXPECT_EQ(restored.learner_epoch, 2u);
  EXPECT_EQ(restored_bytes, agent_bytes);
}

TEST(LearnerCheckpointTest, ForeignOrTruncatedFilesThrow) {
  std::vector<std::uint8_t> bytes;
  const std::string other = "not a checkpoint";
  EXPECT_THROW(unpack_checkpoint(std::vector<std::uint8_t>(other.begin(), other.end()), bytes),
               CheckpointError);
  auto packed = pack_checkpoint({}, std::vector<std::uint8_t>{1, 2});
  packed.resize(35);  // inside the counters line
  EXPECT_THROW(unpack_checkpoint(packed, bytes), CheckpointError);
}

TEST(LearnerCheckpointTest, ReplaySectionRoundTripsCompressed) {
  // A replay file of class-id frames: long runs of few values, as the camera makes them.
  std::vector<std::uint8_t> replay_bytes(200000);
  for (std::size_t i = 0; i < replay_bytes.size(); ++i) replay_bytes[i] = (i / 700) % 8;
  const std::vector<std::uint8_t> agent_bytes = {9, 8, 7};
  const auto packed = pack_checkpoint({.env_steps = 5, .updates = 1}, agent_bytes, replay_bytes);
  EXPECT_LT(packed.size(), replay_bytes.size() / 10) << "zstd shrinks class-id frames";
  std::vector<std::uint8_t> agent_out, replay_out = {1};
  EXPECT_EQ(unpack_checkpoint(packed, agent_out, &replay_out).env_steps, 5);
  EXPECT_EQ(agent_out, agent_bytes);
  EXPECT_EQ(replay_out, replay_bytes);

  // Without a replay section the replay comes back empty.
  const auto bare = pack_checkpoint({}, agent_bytes);
  unpack_checkpoint(bare, agent_out, &replay_out);
  EXPECT_TRUE(replay_out.empty());
  EXPECT_EQ(agent_out, agent_bytes);
}

TEST(LearnerCheckpointTest, TruncatedOrDamagedReplaySectionThrows) {
  std::vector<std::uint8_t> replay_bytes(5000, 3);
  const auto packed = pack_checkpoint({}, std::vector<std::uint8_t>{1, 2, 3}, replay_bytes);
  std::vector<std::uint8_t> agent_out, replay_out;
  auto truncated = packed;
  truncated.pop_back();
  EXPECT_THROW(unpack_checkpoint(truncated, agent_out, &replay_out), CheckpointError);
  auto damaged = packed;
  damaged[damaged.size() - 4] ^= 0xFF;  // inside the zstd frame
  EXPECT_THROW(unpack_checkpoint(damaged, agent_out, &replay_out), CheckpointError);
}

TEST(LearnerCheckpointTest, ReadsTheFormatWithoutReplay) {
  const std::string v1 =
      "INDRIVE-LEARNER-CHECKPOINT 1\n"
      R"({"env_steps":10,"updates":2,"policy_version":3,"learner_epoch":1})"
      "\nAGENT";
  std::vector<std::uint8_t> agent_out, replay_out = {1};
  const auto counters =
      unpack_checkpoint(std::vector<std::uint8_t>(v1.begin(), v1.end()), agent_out, &replay_out);
  EXPECT_EQ(counters.policy_version, 3u);
  EXPECT_EQ(std::string(agent_out.begin(), agent_out.end()), "AGENT");
  EXPECT_TRUE(replay_out.empty());
}

TEST(LearnerCheckpointTest, VersionThreeEndsWithACrcOfEveryByteBeforeIt) {
  const std::vector<std::uint8_t> replay_bytes(3000, 5);
  const auto packed = pack_checkpoint({.env_steps = 12345, .updates = 6},
                                      std::vector<std::uint8_t>{1, 2, 3}, replay_bytes);
  const std::string text(packed.begin(), packed.end());
  EXPECT_TRUE(text.starts_with("INDRIVE-LEARNER-CHECKPOINT 3\n"));
  char expected[kTrailerSize + 1];
  std::snprintf(expected, sizeof expected, "CRC32 %08x\n",
                crc32(std::span(packed).first(packed.size() - kTrailerSize)));
  EXPECT_EQ(text.substr(text.size() - kTrailerSize), expected);
}

TEST(LearnerCheckpointTest, ABitFlipInTheCountersLineIsCaught) {
  const auto packed =
      pack_checkpoint({.env_steps = 12345, .updates = 678}, std::vector<std::uint8_t>{1, 2, 3});
  auto flipped = packed;
  const std::string text(packed.begin(), packed.end());
  const std::size_t digit = text.find("12345") + 4;
  flipped[digit] ^= 0x01;  // '5' -> '4': still a valid counters line
  const std::string error = unpack_error(flipped);
  EXPECT_NE(error.find("damaged"), std::string::npos) << error;
  EXPECT_NE(error.find("CRC-32"), std::string::npos) << error;
  // Why version 3: without the trailer the same flip reads as other counters, unnoticed.
  std::vector<std::uint8_t> agent_out;
  EXPECT_EQ(unpack_checkpoint(as_version_2(flipped), agent_out).env_steps, 12344);
}

TEST(LearnerCheckpointTest, TruncationAnywhereIsCaught) {
  const std::vector<std::uint8_t> replay_bytes(20000, 2);
  const auto packed =
      pack_checkpoint({.env_steps = 1}, std::vector<std::uint8_t>(500, 9), replay_bytes);
  for (const std::size_t keep :
       {std::size_t{0}, std::size_t{20}, std::size_t{40}, packed.size() / 2,
        packed.size() - kTrailerSize, packed.size() - 1}) {
    const std::string error = unpack_error(std::span(packed).first(keep));
    EXPECT_NE(error, "(no error)") << "cut to " << keep << " of " << packed.size() << " bytes";
  }
  EXPECT_NE(unpack_error(std::span(packed).first(packed.size() - 1)).find("trailer"),
            std::string::npos);
}

TEST(LearnerCheckpointTest, VersionTwoWithoutTrailerStaysReadable) {
  std::vector<std::uint8_t> replay_bytes(20000);
  for (std::size_t i = 0; i < replay_bytes.size(); ++i) replay_bytes[i] = (i / 300) % 8;
  const std::vector<std::uint8_t> agent_bytes = {4, 5, 6, 7};
  const auto v2 = as_version_2(
      pack_checkpoint({.env_steps = 77, .updates = 7, .policy_version = 3, .learner_epoch = 2},
                      agent_bytes, replay_bytes));
  std::vector<std::uint8_t> agent_out, replay_out;
  const LearnerCounters counters = unpack_checkpoint(v2, agent_out, &replay_out);
  EXPECT_EQ(counters.env_steps, 77);
  EXPECT_EQ(counters.learner_epoch, 2u);
  EXPECT_EQ(agent_out, agent_bytes);
  EXPECT_EQ(replay_out, replay_bytes);
}

TEST(LearnerCheckpointTest, ANewerFormatVersionIsRefusedByName) {
  auto packed = pack_checkpoint({}, std::vector<std::uint8_t>{1});
  packed[kVersionDigit] = '7';
  const std::string error = unpack_error(packed);
  EXPECT_NE(error.find("format version 7"), std::string::npos) << error;
}

TEST(LearnerCheckpointTest, AHugeDeclaredReplaySizeIsRefusedWithoutAllocatingIt) {
  const std::vector<std::uint8_t> replay_bytes(5000, 3);
  const auto packed = pack_checkpoint({}, std::vector<std::uint8_t>{1, 2}, replay_bytes);
  // Resealed, so the checksum passes and only the bound on the replay section stands between
  // the header's 1e15 bytes and an allocation of them (which would throw std::bad_alloc, not
  // CheckpointError).
  const auto huge = with_counters_line(
      packed, [](nlohmann::json& meta) { meta["replay_bytes"] = std::uint64_t{1000000000000000}; });
  const std::string error = unpack_error(huge);
  EXPECT_NE(error.find("1000000000000000"), std::string::npos) << error;
  EXPECT_NE(unpack_error(as_version_2(huge)), "(no error)");
}

TEST(LearnerCheckpointTest, SectionSizesThatWrapAroundAreRefused) {
  const auto packed =
      pack_checkpoint({}, std::vector<std::uint8_t>(100, 1), std::vector<std::uint8_t>(5000, 3));
  const std::string text(packed.begin(), packed.end());
  const std::size_t begin = text.find('\n') + 1, end = text.find('\n', begin);
  const auto meta = nlohmann::json::parse(text.substr(begin, end - begin));
  const std::uint64_t zstd_size = meta["replay_zstd_bytes"];
  // agent + replay = 2^64 + 100 + zstd_size wraps to the true total of the two sections.
  const auto wrapped = with_counters_line(packed, [&](nlohmann::json& m) {
    m["agent_bytes"] = std::numeric_limits<std::uint64_t>::max();
    m["replay_zstd_bytes"] = zstd_size + 101;
  });
  EXPECT_NE(unpack_error(wrapped).find("bytes after its counters"), std::string::npos)
      << unpack_error(wrapped);
}

// A frame written by zstd's streaming API without a pledged size carries no content size:
// then only the bound of the streaming decompression holds the output to the declared size.
TEST(LearnerCheckpointTest, AFrameWithoutContentSizeStopsAtTheDeclaredSize) {
  const std::vector<std::uint8_t> replay_bytes(200000, 6);
  std::vector<std::uint8_t> frame(ZSTD_compressBound(replay_bytes.size()));
  std::unique_ptr<ZSTD_CCtx, decltype(&ZSTD_freeCCtx)> context(ZSTD_createCCtx(), ZSTD_freeCCtx);
  ZSTD_CCtx_setParameter(context.get(), ZSTD_c_checksumFlag, 1);
  ZSTD_inBuffer in{replay_bytes.data(), replay_bytes.size(), 0};
  ZSTD_outBuffer out{frame.data(), frame.size(), 0};
  // A first call that ends the frame would tell zstd the whole size: continue first.
  ASSERT_FALSE(ZSTD_isError(ZSTD_compressStream2(context.get(), &out, &in, ZSTD_e_continue)));
  std::size_t left = 1;
  while (left != 0) {
    left = ZSTD_compressStream2(context.get(), &out, &in, ZSTD_e_end);
    ASSERT_FALSE(ZSTD_isError(left)) << ZSTD_getErrorName(left);
  }
  frame.resize(out.pos);
  ASSERT_EQ(ZSTD_getFrameContentSize(frame.data(), frame.size()), ZSTD_CONTENTSIZE_UNKNOWN);

  const auto version_2 = [&](std::uint64_t declared) {
    const nlohmann::json meta = {{"env_steps", 1},
                                 {"updates", 0},
                                 {"policy_version", 0},
                                 {"learner_epoch", 0},
                                 {"agent_bytes", 0},
                                 {"replay_bytes", declared},
                                 {"replay_zstd_bytes", frame.size()}};
    auto bytes = bytes_of("INDRIVE-LEARNER-CHECKPOINT 2\n" + meta.dump() + "\n");
    bytes.insert(bytes.end(), frame.begin(), frame.end());
    return bytes;
  };
  std::vector<std::uint8_t> agent_out, replay_out;
  unpack_checkpoint(version_2(replay_bytes.size()), agent_out, &replay_out);
  EXPECT_EQ(replay_out, replay_bytes);
  const std::string more = unpack_error(version_2(1000));
  EXPECT_NE(more.find("more than the 1000 bytes"), std::string::npos) << more;
  const std::string fewer = unpack_error(version_2(300000));
  EXPECT_NE(fewer.find("decompresses to 200000 bytes"), std::string::npos) << fewer;
}

}  // namespace
}  // namespace indrive::learner
