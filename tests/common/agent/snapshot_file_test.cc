// Tests of the snapshot file format's provenance keys (agent/snapshot_file.h); the format's
// other tests (round trip, damaged files, acting-only rewrite) run with the actor's evaluation
// tests in tests/actor/snapshot_file_test.cc.
#include "indrive/agent/snapshot_file.h"

#include <gtest/gtest.h>

#include "indrive/agent/agent.h"
#include "testing.h"

namespace indrive::agent {
namespace {

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
