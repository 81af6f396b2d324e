// Tests of actor/snapshot_file.h, evaluating snapshot files: a missing head is named, the
// file's header sizes the evaluator's model, chosen sizes that differ are refused, and files
// without a header still load with their preset. The format itself is tested in
// tests/common/agent/snapshot_file_test.cc.
#include "indrive/actor/snapshot_file.h"

#include <gtest/gtest.h>

#include <fstream>

#include "eval_test_support.h"
#include "indrive/actor/eval_protocol_record.h"
#include "indrive/actor/policies.h"
#include "indrive/agent/agent.h"
#include "indrive/agent/policy.h"
#include "indrive/envserver/town.h"
#include "testing.h"

namespace indrive::actor {
namespace {

using agent::read_snapshot_file;
using agent::SnapshotFile;
using agent::write_snapshot_file;

using test_support::eval_error_of;
using test_support::tiny_snapshot;

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

void put_bytes(const std::filesystem::path& path, std::span<const std::uint8_t> bytes) {
  std::ofstream(path, std::ios::binary)
      .write(reinterpret_cast<const char*>(bytes.data()),
             static_cast<std::streamsize>(bytes.size()));
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

}  // namespace
}  // namespace indrive::actor
