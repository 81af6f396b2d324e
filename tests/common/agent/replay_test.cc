#include "indrive/agent/replay.h"

#include <gtest/gtest.h>

#include <cstring>
#include <fstream>
#include <iterator>
#include <set>

#include "indrive/basics/checksum.h"
#include "testing.h"

namespace indrive::agent {
namespace {

ReplayStep make_step(int value, bool first = false) {
  ReplayStep s;
  s.frame = std::vector<std::uint8_t>(4, static_cast<std::uint8_t>(value % 8));
  s.action = value % 9;
  s.is_first = first;
  return s;
}

ReplayOptions small_options(bool rewards = false) {
  return {.capacity = 10, .height = 2, .width = 2, .has_rewards = rewards, .seed = 3};
}

TEST(Replay, WindowsStayInsideOneStreamAndStartWithIsFirst) {
  ReplayBuffer replay(small_options());
  // Interleave two streams whose actions encode (stream, index).
  for (int i = 0; i < 4; ++i) {
    ReplayStep a = make_step(i, i == 0);
    a.action = i;  // stream 0: actions 0..3
    replay.add(0, a);
    ReplayStep b = make_step(i, i == 0);
    b.action = 5 + i % 4;  // stream 1: actions 5..8
    replay.add(1, b);
  }
  EXPECT_EQ(replay.num_windows(3), 4);  // 2 per stream
  const SequenceBatch batch = replay.sample(50, 3);
  for (int b = 0; b < 50; ++b) {
    const int a0 = batch.actions[b * 3];
    EXPECT_EQ(batch.is_first[b * 3], 1.0f);
    for (int t = 1; t < 3; ++t) {
      EXPECT_EQ(batch.actions[b * 3 + t], a0 + t) << "window crossed streams";
      EXPECT_EQ(batch.is_first[b * 3 + t], 0.0f);
    }
  }
}

TEST(Replay, SamplingIsUniformOverWindows) {
  ReplayBuffer replay(small_options());
  for (int i = 0; i < 6; ++i) replay.add(0, make_step(i, i == 0));
  ASSERT_EQ(replay.num_windows(2), 5);
  std::vector<int> counts(9, 0);
  const SequenceBatch batch = replay.sample(5000, 2);
  for (int b = 0; b < 5000; ++b) counts[batch.actions[b * 2]]++;
  for (int start = 0; start < 5; ++start) EXPECT_NEAR(counts[start], 1000, 150) << start;
  EXPECT_EQ(counts[5], 0);  // a window cannot start at the newest step
}

TEST(Replay, EvictsTheOldestStepAcrossStreams) {
  ReplayBuffer replay(small_options());
  for (int i = 0; i < 8; ++i) replay.add(0, make_step(i));
  for (int i = 0; i < 4; ++i) replay.add(1, make_step(i));
  EXPECT_EQ(replay.size(), 10);
  EXPECT_EQ(replay.total_added(), 12);
  // Stream 0 lost its two oldest steps: 6 left, 4 windows of 3; stream 1: 2.
  EXPECT_EQ(replay.num_windows(3), 4 + 2);
}

TEST(Replay, EpisodeStartsInsideAWindowKeepIsFirst) {
  ReplayBuffer replay(small_options());
  for (int i = 0; i < 4; ++i) {
    ReplayStep s = make_step(i, i == 0 || i == 2);
    s.is_last = (i == 1);
    s.is_terminal = (i == 1);
    replay.add(0, s);
  }
  const SequenceBatch batch = replay.sample(1, 4);
  EXPECT_EQ(batch.is_first, (std::vector<float>{1, 0, 1, 0}));
  EXPECT_EQ(batch.is_terminal, (std::vector<float>{0, 1, 0, 0}));
}

TEST(Replay, RewardFreeBufferHasNoRewards) {
  ReplayBuffer replay(small_options(false));
  for (int i = 0; i < 4; ++i) replay.add(0, make_step(i));
  EXPECT_TRUE(replay.sample(2, 3).rewards.empty());
  ReplayStep with_reward = make_step(1);
  with_reward.reward = 0.5f;
  EXPECT_THROW(replay.add(0, with_reward), ReplayError);

  ReplayBuffer task(small_options(true));
  for (int i = 0; i < 4; ++i) {
    ReplayStep s = make_step(i);
    s.reward = static_cast<float>(i);
    task.add(0, s);
  }
  const SequenceBatch batch = task.sample(1, 4);
  EXPECT_EQ(batch.rewards, (std::vector<float>{0, 1, 2, 3}));
}

TEST(Replay, MalformedStepsThrow) {
  ReplayBuffer replay(small_options());
  ReplayStep s = make_step(0);
  s.frame.resize(5);
  EXPECT_THROW(replay.add(0, s), ReplayError);
  s = make_step(0);
  s.frame[0] = 8;  // only 8 classes
  EXPECT_THROW(replay.add(0, s), ReplayError);
  s = make_step(0);
  s.action = 9;
  EXPECT_THROW(replay.add(0, s), ReplayError);
}

TEST(Replay, SaveLoadRestoresContentAndRngExactly) {
  indrive::testing::TempDir dir;
  ReplayBuffer a(small_options(true));
  for (int i = 0; i < 7; ++i) {
    ReplayStep s = make_step(i, i == 0);
    s.reward = i * 0.25f;
    a.add(i % 2, s);
  }
  a.save(dir.path() / "replay.bin");
  ReplayBuffer b(small_options(true));
  b.load(dir.path() / "replay.bin");
  EXPECT_EQ(b.size(), a.size());
  EXPECT_EQ(b.total_added(), a.total_added());
  const SequenceBatch x = a.sample(8, 2), y = b.sample(8, 2);
  EXPECT_EQ(x.actions, y.actions);
  EXPECT_EQ(x.frames, y.frames);
  EXPECT_EQ(x.rewards, y.rewards);
}

TEST(Replay, LoadRejectsCorruptOrForeignFiles) {
  indrive::testing::TempDir dir;
  ReplayBuffer a(small_options());
  for (int i = 0; i < 3; ++i) a.add(0, make_step(i));
  const auto path = dir.path() / "replay.bin";
  a.save(path);
  ReplayBuffer with_rewards(small_options(true));
  EXPECT_THROW(with_rewards.load(path), ReplayError);  // pretrain data into a task buffer
  {
    std::fstream f(path, std::ios::in | std::ios::out | std::ios::binary);
    f.seekp(40);
    f.put('\x7f');
  }
  ReplayBuffer b(small_options());
  EXPECT_THROW(b.load(path), ReplayError);
  EXPECT_THROW(b.load(dir.path() / "missing.bin"), ReplayError);
  EXPECT_EQ(b.size(), 0);
}

TEST(Replay, LoadRefusesActionsAndClassIdsThatAddRefuses) {
  indrive::testing::TempDir dir;
  ReplayBuffer a(small_options());
  for (int i = 0; i < 9; ++i) a.add(0, make_step(i));  // actions 0..8, class ids 0..7
  const auto path = dir.path() / "replay.bin";
  a.save(path);
  // Actions or class ids the sampler would hand out of range never load.
  ReplayOptions fewer_actions = small_options();
  fewer_actions.num_actions = 4;
  ReplayBuffer b(fewer_actions);
  EXPECT_THROW(b.load(path), ReplayError);
  ReplayOptions fewer_classes = small_options();
  fewer_classes.num_classes = 4;
  ReplayBuffer c(fewer_classes);
  EXPECT_THROW(c.load(path), ReplayError);
}

TEST(Replay, BytesAreTheFileAndLoadFromMemory) {
  indrive::testing::TempDir dir;
  ReplayBuffer a(small_options());
  for (int i = 0; i < 5; ++i) a.add(0, make_step(i, i == 0));
  a.save(dir.path() / "replay.bin");
  std::ifstream file(dir.path() / "replay.bin", std::ios::binary);
  const std::vector<std::uint8_t> on_disk((std::istreambuf_iterator<char>(file)),
                                          std::istreambuf_iterator<char>());
  const std::vector<std::uint8_t> bytes = a.to_bytes();
  EXPECT_EQ(bytes, on_disk);
  ReplayBuffer b(small_options());
  b.load(bytes, "memory");
  EXPECT_EQ(b.size(), 5);
  EXPECT_EQ(b.sample(4, 2).frames, a.sample(4, 2).frames);
  auto damaged = bytes;
  damaged[30] ^= 0x01;
  ReplayBuffer c(small_options());
  try {
    c.load(damaged, "memory");
    FAIL() << "a damaged buffer loaded";
  } catch (const ReplayError& error) {
    EXPECT_NE(std::string(error.what()).find("replay file memory is corrupt"), std::string::npos)
        << error.what();
  }
  EXPECT_EQ(c.size(), 0);
}

// A size field near 2^64 (with the checksum made to match, as a crafted file would) is refused
// as truncation: neither allocated nor wrapped around past the bounds check.
TEST(Replay, AHugeSizeFieldIsTruncationNotAnAllocation) {
  ReplayBuffer a(small_options());
  a.add(0, make_step(1, true));
  auto bytes = a.to_bytes();
  // magic 4, version 4, height 4, width 4, rewards 1, total added 8: the RNG state's size.
  constexpr std::size_t kRngSizeAt = 25;
  for (const std::uint64_t size : {std::uint64_t{1000000000000000}, ~std::uint64_t{0} - 8}) {
    std::memcpy(bytes.data() + kRngSizeAt, &size, sizeof size);
    const std::uint32_t crc = indrive::crc32(bytes.data(), bytes.size() - 4);
    std::memcpy(bytes.data() + bytes.size() - 4, &crc, sizeof crc);
    ReplayBuffer b(small_options());
    try {
      b.load(bytes, "crafted");
      FAIL() << "a size of " << size << " loaded";
    } catch (const ReplayError& error) {
      EXPECT_NE(std::string(error.what()).find("truncated"), std::string::npos) << error.what();
    }
  }
}

}  // namespace
}  // namespace indrive::agent
