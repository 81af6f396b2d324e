// Tests of snapshot_file.h: groups and heads read without loading, files written and read,
// the architecture header, and clear errors for files that are not what they claim.
#include "indrive/actor/snapshot_file.h"

#include <gtest/gtest.h>

#include <cstring>
#include <fstream>
#include <numbers>

#include "eval_test_support.h"
#include "indrive/actor/policies.h"
#include "indrive/actor/protocol_record.h"
#include "indrive/agent/agent.h"
#include "indrive/agent/policy.h"
#include "indrive/basics/checksum.h"
#include "indrive/envserver/town.h"
#include "indrive/nn/serialize.h"
#include "testing.h"

namespace indrive::actor {
namespace {

using agent::describe_snapshot_file;
using agent::kSnapshotFileFormat;
using agent::read_snapshot_file;
using agent::snapshot_architecture_keys;
using agent::snapshot_groups;
using agent::SnapshotFile;
using agent::write_acting_snapshot_file;
using agent::write_snapshot_file;

using test_support::eval_error_of;
using test_support::tiny_snapshot;

TEST(SnapshotFile, SnapshotGroupsAreReadWithoutLoading) {
  const auto pretrain = tiny_snapshot(agent::Phase::kPretrain);
  const auto groups = snapshot_groups(pretrain);
  ASSERT_EQ(groups.size(), 2u);
  EXPECT_EQ(groups.back(), "expl_actor");
  const auto finetune = tiny_snapshot(agent::Phase::kFinetune);
  EXPECT_EQ(snapshot_groups(finetune).back(), "task_actor");
  EXPECT_EQ(snapshot_groups(finetune).front(), groups.front());  // the same world model group

  // A flipped byte fails the checksum; a cut blob is not one.
  auto corrupt = pretrain;
  corrupt[corrupt.size() / 2] ^= 0x5a;
  EXPECT_NE(eval_error_of([&] { snapshot_groups(corrupt); }).find("checksum"), std::string::npos);
  const std::vector<std::uint8_t> cut(pretrain.begin(), pretrain.begin() + 10);
  EXPECT_FALSE(eval_error_of([&] { snapshot_groups(cut); }).empty());
}

TEST(SnapshotFile, SnapshotMissingTheRequestedHeadIsAClearError) {
  const auto pretrain = tiny_snapshot(agent::Phase::kPretrain);
  EXPECT_NO_THROW(check_snapshot_head(pretrain, PolicyHead::kExploration, "snapshot file a"));
  const std::string message =
      eval_error_of([&] { check_snapshot_head(pretrain, PolicyHead::kTask, "snapshot file a"); });
  EXPECT_NE(message.find("snapshot file a"), std::string::npos) << message;
  EXPECT_NE(message.find("not task_actor"), std::string::npos) << message;
  EXPECT_NE(message.find("few-shot"), std::string::npos) << message;
  EXPECT_NE(message.find("eval.kind=zero_shot"), std::string::npos) << message;

  const auto finetune = tiny_snapshot(agent::Phase::kFinetune);
  EXPECT_NE(eval_error_of([&] {
              check_snapshot_head(finetune, PolicyHead::kExploration, "x");
            }).find("not expl_actor"),
            std::string::npos);

  // Through the policy factory too, before any network is built.
  agent::AgentConfig config = agent::preset("tiny");
  EXPECT_FALSE(eval_error_of([&] {
                 make_snapshot_policy(config, pretrain, PolicyHead::kTask, "s");
               }).empty());
  EXPECT_NE(make_snapshot_policy(config, pretrain, PolicyHead::kExploration, "s"), nullptr);
  EXPECT_NE(make_snapshot_policy(config, finetune, PolicyHead::kTask, "s"), nullptr);
}

TEST(SnapshotFile, SnapshotOfAnotherPresetNamesThePreset) {
  const auto pretrain = tiny_snapshot(agent::Phase::kPretrain);
  const std::string message = eval_error_of([&] {
    make_snapshot_policy(agent::preset("cpu"), pretrain, PolicyHead::kExploration, "file f");
  });
  EXPECT_NE(message.find("file f does not fit the configured model (preset cpu)"),
            std::string::npos)
      << message;
}

TEST(SnapshotFile, SnapshotFilesRoundTripAndBadFilesAreNamed) {
  testing::TempDir dir;
  const auto blob = tiny_snapshot(agent::Phase::kPretrain);
  write_snapshot_file(dir.path() / "snapshot-v3.params", blob, agent::preset("tiny"));
  const SnapshotFile file = read_snapshot_file(dir.path() / "snapshot-v3.params");
  EXPECT_EQ(file.blob, blob);
  EXPECT_EQ(file.format, kSnapshotFileFormat);
  EXPECT_EQ(file.value("preset"), "tiny");
  EXPECT_EQ(file.value("phase"), "pretrain");
  EXPECT_EQ(file.value("actor"), "expl_actor");
  EXPECT_EQ(file.value("world_model.image"), "32");
  EXPECT_EQ(file.value("behavior.layers"), "2");
  ASSERT_EQ(file.architecture.size(), snapshot_architecture_keys().size());
  for (std::size_t i = 0; i < file.architecture.size(); ++i) {
    EXPECT_EQ(file.architecture[i].first, snapshot_architecture_keys()[i]);
  }

  const auto missing = dir.path() / "nope.params";
  std::string message = eval_error_of([&] { read_snapshot_file(missing); });
  EXPECT_NE(message.find(missing.string()), std::string::npos) << message;
  EXPECT_NE(message.find("does not exist"), std::string::npos) << message;

  std::ofstream(dir.path() / "empty.params").close();
  EXPECT_NE(eval_error_of([&] { read_snapshot_file(dir.path() / "empty.params"); }).find("empty"),
            std::string::npos);
  std::ofstream(dir.path() / "text.params") << "this is not a snapshot at all";
  EXPECT_FALSE(eval_error_of([&] { read_snapshot_file(dir.path() / "text.params"); }).empty());

  // The writer refuses a blob whose actor is not its phase's.
  agent::AgentConfig finetune = agent::preset("tiny");
  finetune.phase = agent::Phase::kFinetune;
  message = eval_error_of([&] { write_snapshot_file(dir.path() / "x.params", blob, finetune); });
  EXPECT_NE(message.find("acts with task_actor"), std::string::npos) << message;
}

// The bytes of a file on disk.
std::vector<std::uint8_t> file_bytes(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

void put_bytes(const std::filesystem::path& path, std::span<const std::uint8_t> bytes) {
  std::ofstream(path, std::ios::binary)
      .write(reinterpret_cast<const char*>(bytes.data()),
             static_cast<std::streamsize>(bytes.size()));
}

// A format-1 file built by hand from its parts, as snapshot_file.h documents the format.
std::vector<std::uint8_t> handmade_file(std::uint32_t version, const std::string& header,
                                        std::span<const std::uint8_t> blob) {
  std::vector<std::uint8_t> bytes = {'I', 'N', 'D', 'R', 'S', 'N', 'A', 'P'};
  auto u32 = [&](std::uint32_t v) {
    for (int i = 0; i < 4; ++i) bytes.push_back(static_cast<std::uint8_t>(v >> (8 * i)));
  };
  u32(version);
  u32(static_cast<std::uint32_t>(header.size()));
  bytes.insert(bytes.end(), header.begin(), header.end());
  u32(crc32(bytes.data(), bytes.size()));
  bytes.insert(bytes.end(), blob.begin(), blob.end());
  return bytes;
}

TEST(SnapshotFile, TinySnapshotFileEvaluatesWithTheDefaultConfig) {
  testing::TempDir dir;
  agent::AgentConfig tiny = agent::preset("tiny");
  agent::Agent agent(tiny);
  const auto path = dir.path() / "snapshot-v5.params";
  write_snapshot_file(path, agent.snapshot(), tiny);

  // What an evaluator with no preset or size given holds: the cpu defaults, nothing chosen.
  agent::AgentConfig config = agent::preset("cpu");
  const SnapshotFile file = read_snapshot_file(path);
  const std::string note = adopt_snapshot_architecture(config, file, {}, "snapshot file f");
  EXPECT_EQ(config.preset, "tiny");
  EXPECT_EQ(config.world_model.image, 32);
  EXPECT_EQ(config.world_model.deter, 128);
  EXPECT_EQ(config.world_model.stoch, 16);
  EXPECT_EQ(config.behavior.units, 128);
  EXPECT_NE(note.find("snapshot file f"), std::string::npos) << note;
  EXPECT_NE(note.find("preset tiny"), std::string::npos) << note;
  EXPECT_NE(note.find("world_model.image=32"), std::string::npos) << note;

  EXPECT_NE(make_snapshot_policy(config, file.blob, PolicyHead::kExploration, "f"), nullptr);
  // One action from the snapshot's weights on a frame of the file's image size.
  agent::Policy policy(config);
  policy.load_snapshot(file.blob);
  agent::PolicyState state;
  const std::vector<std::uint8_t> frame(32 * 32, 1);
  const int action = policy.act_eval(frame, true, state);
  EXPECT_GE(action, 0);
  EXPECT_LT(action, agent::kNumActions);

  // A finetune snapshot's header brings its phase along (the results' method follows it).
  agent::AgentConfig dreamer = tiny;
  dreamer.phase = agent::Phase::kDreamer;
  write_snapshot_file(path, agent::Agent(dreamer).snapshot(), dreamer);
  config = agent::preset("cpu");
  adopt_snapshot_architecture(config, read_snapshot_file(path), {}, "f");
  EXPECT_EQ(config.phase, agent::Phase::kDreamer);
  EXPECT_EQ(config.preset, "tiny");
}

TEST(SnapshotFile, ChosenSizesThatDifferFromTheFileAreAClearError) {
  testing::TempDir dir;
  const auto path = dir.path() / "s.params";
  write_snapshot_file(path, tiny_snapshot(agent::Phase::kPretrain), agent::preset("tiny"));
  const SnapshotFile file = read_snapshot_file(path);

  // --set preset=cpu: every size the cpu preset sets is chosen.
  agent::AgentConfig config = agent::preset("cpu");
  std::string message = eval_error_of([&] {
    adopt_snapshot_architecture(config, file, {{"preset", "--set preset=cpu"}}, "snapshot file f");
  });
  EXPECT_NE(message.find("snapshot file f was trained with preset tiny"), std::string::npos)
      << message;
  EXPECT_NE(message.find("world_model.image=64 (preset cpu from --set preset=cpu) where the file "
                         "has 32"),
            std::string::npos)
      << message;
  EXPECT_NE(message.find("drop --set preset=cpu"), std::string::npos) << message;

  // One explicit size among the file's: it alone conflicts; it is named with where it was set.
  config = agent::preset("tiny");
  config.world_model.deter = 256;
  message = eval_error_of([&] {
    adopt_snapshot_architecture(config, file,
                                {{"world_model.deter", "--set agent.world_model.deter=256"}}, "f");
  });
  EXPECT_NE(message.find("world_model.deter=256 (--set agent.world_model.deter=256) where the "
                         "file has 128"),
            std::string::npos)
      << message;
  EXPECT_EQ(message.find("world_model.image=64"), std::string::npos) << message;
  EXPECT_NE(message.find("or set them to the file's values"), std::string::npos) << message;

  // Chosen sizes that agree with the file are fine, and the configured preset stays.
  config = agent::preset("tiny");
  const std::string note = adopt_snapshot_architecture(
      config, file, {{"preset", "--set preset=tiny"}, {"world_model.deter", "preset 'tiny'"}}, "f");
  EXPECT_EQ(config.world_model.image, 32);
  EXPECT_NE(note.find("as configured"), std::string::npos) << note;
}

// A file of the whole world model (as written before snapshots left the decoder out) is said to
// be one, and is rewritten with what acting runs: the header kept, the blob the one that
// Agent::snapshot() gives now.
TEST(SnapshotFile, AnOlderWholeWorldModelFileIsRewrittenWithWhatActingRuns) {
  testing::TempDir dir;
  agent::AgentConfig tiny = agent::preset("tiny");
  agent::Agent agent(tiny);
  const nn::ParamGroup* whole_groups[] = {&agent.world_model().params(),
                                          &agent.exploration().actor_params()};
  const auto whole = nn::save_params(whole_groups);
  const auto old_path = dir.path() / "old.params";
  write_snapshot_file(old_path, whole, tiny);
  const SnapshotFile old_file = read_snapshot_file(old_path);
  const std::string old_text = describe_snapshot_file(old_file);
  EXPECT_NE(old_text.find("preset = tiny"), std::string::npos) << old_text;
  EXPECT_NE(old_text.find("the whole world model: 18 parameters acting does not run"),
            std::string::npos)
      << old_text;
  EXPECT_NE(old_text.find("--acting-only"), std::string::npos) << old_text;

  const auto new_path = dir.path() / "acting.params";
  write_acting_snapshot_file(new_path, old_file);
  const SnapshotFile acting = read_snapshot_file(new_path);
  EXPECT_EQ(acting.architecture, old_file.architecture);
  EXPECT_EQ(acting.blob, agent.snapshot());
  EXPECT_LT(std::filesystem::file_size(new_path), std::filesystem::file_size(old_path) * 6 / 10);
  const std::string text = describe_snapshot_file(acting);
  EXPECT_NE(text.find("what acting runs (encoder, RSSM)"), std::string::npos) << text;
  EXPECT_NE(text.find("group expl_actor: 8 parameters"), std::string::npos) << text;

  // A bare blob has no header to keep: refused, saying what to do instead.
  put_bytes(old_path, whole);
  const std::string message =
      eval_error_of([&] { write_acting_snapshot_file(new_path, read_snapshot_file(old_path)); });
  EXPECT_NE(message.find("--set preset=NAME"), std::string::npos) << message;
}

TEST(SnapshotFile, SnapshotFileWithoutHeaderStillLoadsWithItsPreset) {
  testing::TempDir dir;
  const auto blob = tiny_snapshot(agent::Phase::kPretrain);
  const auto path = dir.path() / "old.params";
  put_bytes(path, blob);  // format 0: the bare blob, as files were written before the header
  const SnapshotFile file = read_snapshot_file(path);
  EXPECT_EQ(file.format, 0u);
  EXPECT_EQ(file.blob, blob);
  EXPECT_TRUE(file.architecture.empty());

  agent::AgentConfig config = agent::preset("tiny");
  EXPECT_EQ(adopt_snapshot_architecture(config, file, {{"preset", "--set preset=tiny"}}, "f"), "");
  EXPECT_NE(make_snapshot_policy(config, file.blob, PolicyHead::kExploration, "f"), nullptr);

  // Without the preset: the old behaviour, the old message.
  config = agent::preset("cpu");
  EXPECT_EQ(adopt_snapshot_architecture(config, file, {}, "f"), "");
  EXPECT_EQ(config.world_model.image, 64) << "nothing to take from a file without a header";
  const std::string message = eval_error_of([&] {
    make_snapshot_policy(config, file.blob, PolicyHead::kExploration, "snapshot file f");
  });
  EXPECT_NE(message.find("snapshot file f does not fit the configured model (preset cpu)"),
            std::string::npos)
      << message;
}

// A small parameter blob of a world model and an exploration actor, a few hundred bytes, so
// thousands of corrupted files stay cheap to write.
std::vector<std::uint8_t> small_blob() {
  nn::ParamGroup world_model("world_model");
  world_model.add("w", nn::Shape({2, 3}));
  nn::ParamGroup actor("expl_actor");
  actor.add("b", nn::Shape({4}));
  const nn::ParamGroup* groups[] = {&world_model, &actor};
  return nn::save_params(groups);
}

TEST(SnapshotFile, TruncatedOrFlippedHeaderIsRejectedWithAMessage) {
  testing::TempDir dir;
  const auto good = dir.path() / "good.params";
  write_snapshot_file(good, small_blob(), agent::preset("tiny"));
  const std::vector<std::uint8_t> bytes = file_bytes(good);
  std::uint32_t header_length = 0;
  std::memcpy(&header_length, bytes.data() + 12, 4);
  const std::size_t header_end = 16 + header_length + 4;  // prefix, text, checksum
  ASSERT_LT(header_end, bytes.size());
  const auto bad = dir.path() / "bad.params";

  // Every cut inside the header, and a few inside the blob.
  for (std::size_t size :
       {std::size_t{1}, std::size_t{4}, std::size_t{8}, std::size_t{12}, std::size_t{16},
        std::size_t{19}, std::size_t{40}, header_end - 5, header_end - 1, header_end,
        header_end + 3, header_end + 30, bytes.size() - 1}) {
    put_bytes(bad, std::span(bytes).first(size));
    const std::string message = eval_error_of([&] { read_snapshot_file(bad); });
    EXPECT_NE(message.find(bad.string()), std::string::npos)
        << "cut at " << size << ": " << message;
  }
  // Every bit of every header byte flipped, one at a time.
  for (std::size_t i = 0; i < header_end; ++i) {
    for (int bit = 0; bit < 8; ++bit) {
      std::vector<std::uint8_t> flipped = bytes;
      flipped[i] ^= static_cast<std::uint8_t>(1u << bit);
      put_bytes(bad, flipped);
      const std::string message = eval_error_of([&] { read_snapshot_file(bad); });
      ASSERT_NE(message.find(bad.string()), std::string::npos)
          << "byte " << i << " bit " << bit << ": " << message;
    }
  }
  std::vector<std::uint8_t> flipped = bytes;
  flipped[20] ^= 0x10;  // in the header text
  put_bytes(bad, flipped);
  EXPECT_NE(eval_error_of([&] { read_snapshot_file(bad); }).find("header checksum mismatch"),
            std::string::npos);

  // Headers with a valid checksum but wrong contents, and a newer format.
  const auto blob = small_blob();
  std::string header;
  for (const auto& [key, value] : read_snapshot_file(good).architecture) {
    header += key + "=" + value + "\n";
  }
  auto message_of = [&](std::uint32_t version, const std::string& text) {
    put_bytes(bad, handmade_file(version, text, blob));
    return eval_error_of([&] { read_snapshot_file(bad); });
  };
  EXPECT_EQ(message_of(1, header), "") << "the handmade file is a valid one";
  EXPECT_NE(message_of(2, header).find("format version 2, this build reads"), std::string::npos);
  std::string text = header.substr(0, header.find("world_model.deter"));
  EXPECT_NE(message_of(1, text).find("lacks the key world_model.deter"), std::string::npos);
  text = header;
  text.replace(text.find("image=32"), 8, "image=big");
  EXPECT_NE(message_of(1, text).find("cannot parse 'big'"), std::string::npos);
  EXPECT_NE(message_of(1, header + "no equals sign\n").find("is not key=value"), std::string::npos);
  EXPECT_NE(message_of(1, header.substr(0, header.size() - 1)).find("lacks a newline"),
            std::string::npos);
  text = header;
  text.replace(text.find("actor=expl_actor"), 16, "actor=task_actor");
  EXPECT_NE(message_of(1, text).find("names the actor task_actor"), std::string::npos);
}

}  // namespace
}  // namespace indrive::actor
