// The agent's checkpoint (agent_checkpoint.cc): an exact resume, the bytes that are the file,
// typed errors for damaged, crafted and foreign files, and files from before the continuation
// head's optimiser section.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <fstream>
#include <iterator>

#include "agent_test_support.h"
#include "indrive/agent/agent.h"
#include "indrive/basics/checksum.h"
#include "testing.h"

namespace indrive::agent {
namespace {

using namespace test_support;  // tiny_config, dot_replay, values_named, ...

// The continuation head's optimiser state travels in the checkpoint as a last section; a
// checkpoint written before it existed (without that section) still loads, the optimiser fresh.
TEST(Agent, CheckpointsWithoutTheContinuationOptimiserStillLoad) {
  nn::set_threads(1);
  AgentConfig config = tiny_config(Phase::kFinetune);
  config.finetune_cont = true;
  ReplayBuffer replay = dot_replay_with_terminals();
  const SequenceBatch b1 = replay.sample(4, 10), b2 = replay.sample(4, 10);
  Agent a(config);
  a.train_step(b1);
  const std::vector<std::uint8_t> bytes = a.checkpoint_bytes();
  // With the section: the next step is the same bitwise.
  Agent b(config);
  b.load_checkpoint(bytes, "with");
  // Without it: the sections up to the counters, the checksum redone.
  std::size_t pos = 8, last = 0;
  while (pos < bytes.size() - 4) {
    std::uint64_t size = 0;
    std::memcpy(&size, bytes.data() + pos, sizeof size);
    last = pos;
    pos += sizeof size + size;
  }
  ASSERT_EQ(pos, bytes.size() - 4);
  std::vector<std::uint8_t> old(bytes.begin(), bytes.begin() + static_cast<std::ptrdiff_t>(last));
  const std::uint32_t crc = indrive::crc32(old.data(), old.size());
  const auto* c = reinterpret_cast<const std::uint8_t*>(&crc);
  old.insert(old.end(), c, c + 4);
  Agent fresh(config);
  fresh.load_checkpoint(old, "old");
  EXPECT_EQ(fresh.train_steps(), 1);
  const TrainMetrics ma = a.train_step(b2), mb = b.train_step(b2), mf = fresh.train_step(b2);
  EXPECT_EQ(ma, mb);
  const auto head_a = values_named(a.world_model().params(), true);
  EXPECT_EQ(values_named(b.world_model().params(), true), head_a);
  // A fresh optimiser takes another first step (its moments and bias correction start anew).
  EXPECT_NE(values_named(fresh.world_model().params(), true), head_a);
  // Anything after the last section is refused.
  std::vector<std::uint8_t> longer(bytes.begin(), bytes.end() - 4);
  const std::uint64_t zero = 0;
  const auto* z = reinterpret_cast<const std::uint8_t*>(&zero);
  longer.insert(longer.end(), z, z + sizeof zero);
  const std::uint32_t crc2 = indrive::crc32(longer.data(), longer.size());
  const auto* c2 = reinterpret_cast<const std::uint8_t*>(&crc2);
  longer.insert(longer.end(), c2, c2 + 4);
  EXPECT_THROW(fresh.load_checkpoint(longer, "longer"), AgentError);
}

TEST(Agent, CheckpointResumesExactly) {
  nn::set_threads(1);
  indrive::testing::TempDir dir;
  ReplayBuffer replay = dot_replay(false);
  const SequenceBatch b1 = replay.sample(2, 8), b2 = replay.sample(2, 8);
  Agent a(tiny_config(Phase::kPretrain, Method::kIcm));
  a.train_step(b1);
  a.save_checkpoint(dir.path() / "a.ckpt");
  AgentConfig other_seed = tiny_config(Phase::kPretrain, Method::kIcm);
  other_seed.seed = 99;  // different initial parameters and RNG: all must come from the file
  Agent b(other_seed);
  b.load_checkpoint(dir.path() / "a.ckpt");
  EXPECT_EQ(b.train_steps(), 1);
  // Every loss of the next step depends on parameters, optimiser-free state, normalisers and
  // the RNG: all must be restored for the metrics to match bitwise.
  const TrainMetrics ma = a.train_step(b2);
  const TrainMetrics mb = b.train_step(b2);
  EXPECT_EQ(ma, mb);
  // After the update, parameters agree to the last bits; bias-gradient reductions may round
  // differently with another buffer alignment, so a relative 1e-5 is allowed.
  auto ga = a.groups(), gb = b.groups();
  ASSERT_EQ(ga.size(), gb.size());
  for (std::size_t i = 0; i < ga.size(); ++i) {
    for (std::size_t k = 0; k < ga[i]->params().size(); ++k) {
      const auto& pa = *ga[i]->params()[k];
      const auto& pb = *gb[i]->params()[k];
      for (std::size_t j = 0; j < pa.value().size(); ++j) {
        ASSERT_NEAR(pa.value()[j], pb.value()[j], 1e-9 + 1e-5 * std::abs(pa.value()[j]))
            << pa.name() << " of " << ga[i]->name();
      }
    }
  }
}

TEST(Agent, CheckpointErrorsAreTyped) {
  indrive::testing::TempDir dir;
  Agent a(tiny_config());
  const auto path = dir.path() / "a.ckpt";
  a.save_checkpoint(path);
  Agent other_method(tiny_config(Phase::kPretrain, Method::kRnd));
  EXPECT_THROW(other_method.load_checkpoint(path), AgentError);
  EXPECT_THROW(a.load_checkpoint(dir.path() / "missing.ckpt"), AgentError);
  {
    std::fstream f(path, std::ios::in | std::ios::out | std::ios::binary);
    f.seekp(100);
    f.put('\x55');
  }
  EXPECT_THROW(a.load_checkpoint(path), AgentError);
}

TEST(Agent, CheckpointBytesAreTheFileAndLoadFromMemory) {
  indrive::testing::TempDir dir;
  Agent a(tiny_config());
  const auto path = dir.path() / "a.ckpt";
  a.save_checkpoint(path);
  std::ifstream file(path, std::ios::binary);
  const std::vector<std::uint8_t> on_disk((std::istreambuf_iterator<char>(file)),
                                          std::istreambuf_iterator<char>());
  const std::vector<std::uint8_t> bytes = a.checkpoint_bytes();
  EXPECT_EQ(bytes, on_disk);
  AgentConfig other_seed = tiny_config();
  other_seed.seed = 99;
  Agent b(other_seed);
  b.load_checkpoint(bytes, "memory");
  EXPECT_EQ(b.snapshot(), a.snapshot()) << "every parameter came from the bytes";
  auto damaged = bytes;
  damaged[100] ^= 0x01;
  try {
    b.load_checkpoint(damaged, "memory");
    FAIL() << "a damaged checkpoint loaded";
  } catch (const AgentError& error) {
    EXPECT_NE(std::string(error.what()).find("checkpoint memory is corrupt"), std::string::npos)
        << error.what();
  }
}

// A section size near 2^64 (with the checksum made to match, as a crafted file would) is
// refused as truncation instead of wrapping around past the bounds check.
TEST(Agent, ASectionSizeThatWrapsAroundIsTruncation) {
  Agent a(tiny_config());
  auto bytes = a.checkpoint_bytes();
  const std::uint64_t size = ~std::uint64_t{0} - 4;
  std::memcpy(bytes.data() + 8, &size, sizeof size);  // the first section, after magic + version
  const std::uint32_t crc = indrive::crc32(bytes.data(), bytes.size() - 4);
  std::memcpy(bytes.data() + bytes.size() - 4, &crc, sizeof crc);
  try {
    a.load_checkpoint(bytes, "crafted");
    FAIL() << "a wrapped section size loaded";
  } catch (const AgentError& error) {
    EXPECT_NE(std::string(error.what()).find("checkpoint crafted is truncated"), std::string::npos)
        << error.what();
  }
}

}  // namespace
}  // namespace indrive::agent
