// Tests of the snapshot file format (agent/snapshot_file.h): groups read without loading,
// files written and read, the header and its provenance keys, the acting-only rewrite, and
// clear errors for files that are not what they claim. What evaluating a file means (heads,
// sizes taken from the header) is tested in tests/actor/snapshot_file_test.cc.
#include "indrive/agent/snapshot_file.h"

#include <gtest/gtest.h>

#include <cstring>
#include <fstream>

#include "indrive/agent/agent.h"
#include "indrive/basics/checksum.h"
#include "indrive/nn/serialize.h"
#include "testing.h"

namespace indrive::agent {
namespace {

// The message of the SnapshotFileError `body` throws ("" when it throws nothing).
template <typename F>
std::string error_of(F&& body) {
  try {
    body();
  } catch (const SnapshotFileError& error) {
    return error.what();
  }
  return "";
}

std::vector<std::uint8_t> tiny_snapshot(Phase phase) {
  AgentConfig config = preset("tiny");
  config.phase = phase;
  return Agent(config).snapshot();
}

void put_bytes(const std::filesystem::path& path, std::span<const std::uint8_t> bytes) {
  std::ofstream(path, std::ios::binary)
      .write(reinterpret_cast<const char*>(bytes.data()),
             static_cast<std::streamsize>(bytes.size()));
}

TEST(SnapshotFileFormat, SnapshotGroupsAreReadWithoutLoading) {
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
  EXPECT_NE(error_of([&] { snapshot_groups(corrupt); }).find("checksum"), std::string::npos);
  const std::vector<std::uint8_t> cut(pretrain.begin(), pretrain.begin() + 10);
  EXPECT_FALSE(error_of([&] { snapshot_groups(cut); }).empty());
}

TEST(SnapshotFileFormat, SnapshotFilesRoundTripAndBadFilesAreNamed) {
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
  std::string message = error_of([&] { read_snapshot_file(missing); });
  EXPECT_NE(message.find(missing.string()), std::string::npos) << message;
  EXPECT_NE(message.find("does not exist"), std::string::npos) << message;

  std::ofstream(dir.path() / "empty.params").close();
  EXPECT_NE(error_of([&] { read_snapshot_file(dir.path() / "empty.params"); }).find("empty"),
            std::string::npos);
  std::ofstream(dir.path() / "text.params") << "this is not a snapshot at all";
  EXPECT_FALSE(error_of([&] { read_snapshot_file(dir.path() / "text.params"); }).empty());

  // The writer refuses a blob whose actor is not its phase's.
  agent::AgentConfig finetune = agent::preset("tiny");
  finetune.phase = agent::Phase::kFinetune;
  message = error_of([&] { write_snapshot_file(dir.path() / "x.params", blob, finetune); });
  EXPECT_NE(message.find("acts with task_actor"), std::string::npos) << message;
}

// The bytes of a file on disk.
std::vector<std::uint8_t> file_bytes(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
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

// A file of the whole world model (as written before snapshots left the decoder out) is said to
// be one, and is rewritten with what acting runs: the header kept, the blob the one that
// Agent::snapshot() gives now.
TEST(SnapshotFileFormat, AnOlderWholeWorldModelFileIsRewrittenWithWhatActingRuns) {
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
      error_of([&] { write_acting_snapshot_file(new_path, read_snapshot_file(old_path)); });
  EXPECT_NE(message.find("--set preset=NAME"), std::string::npos) << message;
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

TEST(SnapshotFileFormat, TruncatedOrFlippedHeaderIsRejectedWithAMessage) {
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
    const std::string message = error_of([&] { read_snapshot_file(bad); });
    EXPECT_NE(message.find(bad.string()), std::string::npos)
        << "cut at " << size << ": " << message;
  }
  // Every bit of every header byte flipped, one at a time.
  for (std::size_t i = 0; i < header_end; ++i) {
    for (int bit = 0; bit < 8; ++bit) {
      std::vector<std::uint8_t> flipped = bytes;
      flipped[i] ^= static_cast<std::uint8_t>(1u << bit);
      put_bytes(bad, flipped);
      const std::string message = error_of([&] { read_snapshot_file(bad); });
      ASSERT_NE(message.find(bad.string()), std::string::npos)
          << "byte " << i << " bit " << bit << ": " << message;
    }
  }
  std::vector<std::uint8_t> flipped = bytes;
  flipped[20] ^= 0x10;  // in the header text
  put_bytes(bad, flipped);
  EXPECT_NE(error_of([&] { read_snapshot_file(bad); }).find("header checksum mismatch"),
            std::string::npos);

  // Headers with a valid checksum but wrong contents, and a newer format.
  const auto blob = small_blob();
  std::string header;
  for (const auto& [key, value] : read_snapshot_file(good).architecture) {
    header += key + "=" + value + "\n";
  }
  auto message_of = [&](std::uint32_t version, const std::string& text) {
    put_bytes(bad, handmade_file(version, text, blob));
    return error_of([&] { read_snapshot_file(bad); });
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

TEST(SnapshotFileProvenance, RunVersionAndStepsRoundTripAndOlderReadersIgnoreThem) {
  testing::TempDir dir;
  const AgentConfig tiny = preset("tiny");
  const auto blob = Agent(tiny).snapshot();
  const auto with = dir.path() / "with.params";
  write_snapshot_file(
      with, blob, tiny,
      SnapshotProvenance{.run_id = "pretrain-s0", .version = 42, .env_steps = 9000});
  const SnapshotFile file = read_snapshot_file(with);
  const auto provenance = file.provenance();
  ASSERT_TRUE(provenance.has_value());
  EXPECT_EQ(provenance->run_id, "pretrain-s0");
  EXPECT_EQ(provenance->version, 42u);
  EXPECT_EQ(provenance->env_steps, 9000u);
  EXPECT_EQ(file.blob, blob);
  // The architecture keys come first, in their order, the provenance after them.
  ASSERT_EQ(file.architecture.size(), snapshot_architecture_keys().size() + 3);
  for (std::size_t i = 0; i < snapshot_architecture_keys().size(); ++i) {
    EXPECT_EQ(file.architecture[i].first, snapshot_architecture_keys()[i]);
  }
  const std::string text = describe_snapshot_file(file);
  EXPECT_NE(text.find("version = 42"), std::string::npos) << text;
  // The acting-only rewrite keeps the whole header.
  write_acting_snapshot_file(dir.path() / "acting.params", file);
  EXPECT_EQ(read_snapshot_file(dir.path() / "acting.params").provenance()->version, 42u);

  // Without provenance (the evaluator's files before, `indrive snapshot --untrained`): none.
  const auto without = dir.path() / "without.params";
  write_snapshot_file(without, blob, tiny);
  EXPECT_FALSE(read_snapshot_file(without).provenance().has_value());
  EXPECT_EQ(read_snapshot_file(without).architecture.size(), snapshot_architecture_keys().size());
}

TEST(SnapshotFileProvenance, AValueThatIsNotACountGivesNoProvenance) {
  SnapshotFile file;
  file.architecture = {{"run_id", "r"}, {"version", "12"}, {"env_steps", "1e3"}};
  EXPECT_FALSE(file.provenance().has_value());
  file.architecture[2].second = "-5";
  EXPECT_FALSE(file.provenance().has_value());
  file.architecture[2].second = "1000";
  ASSERT_TRUE(file.provenance().has_value());
  EXPECT_EQ(file.provenance()->env_steps, 1000u);
  file.architecture[0].second = "";
  EXPECT_FALSE(file.provenance().has_value()) << "a provenance names its run";
}

}  // namespace
}  // namespace indrive::agent
