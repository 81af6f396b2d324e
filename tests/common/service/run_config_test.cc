#include "indrive/service/run_config.h"

#include <gtest/gtest.h>

#include <fstream>

#include "testing.h"

namespace indrive::service {
namespace {

TEST(ServiceConfigTest, PresetFileAndOverridesReachTheAgentAndEnvironment) {
  testing::TempDir dir;
  const auto file = dir.path() / "run.yaml";
  std::ofstream(file) << "preset: tiny\nagent:\n  intrinsic:\n    method: icm\n"
                         "learner:\n  replay_ratio: 16\n";
  const auto config = ServiceConfig::resolve({.config_file = file,
                                              .run_dir = dir.path() / "runs" / "my-run",
                                              .domain_id = 42,
                                              .overrides = {"agent.replay.batch=4"}});
  EXPECT_EQ(config.run_id(), "my-run");
  EXPECT_EQ(config.domain_id(), 42);
  const auto agent = config.agent();
  EXPECT_EQ(agent.preset, "tiny");
  EXPECT_EQ(agent.world_model.image, 32);
  EXPECT_EQ(agent.world_model.deter, 128);
  EXPECT_EQ(agent.intrinsic.method, agent::Method::kIcm);
  EXPECT_EQ(agent.replay.batch, 4);
  EXPECT_DOUBLE_EQ(config.config().get<double>("learner.replay_ratio"), 16.0);
  EXPECT_EQ(config.wire_phase(), msg::PHASE_PRETRAIN);
}

TEST(ServiceConfigTest, AgentChoicesNameWhatTheConfigurationChose) {
  testing::TempDir dir;
  const auto defaults = ServiceConfig::resolve({.run_dir = dir.path() / "r"});
  EXPECT_TRUE(defaults.agent_choices().empty()) << "nothing chosen: every agent key is a default";

  const auto config = ServiceConfig::resolve(
      {.run_dir = dir.path() / "r", .overrides = {"preset=tiny", "agent.world_model.deter=64"}});
  const auto choices = config.agent_choices();
  EXPECT_EQ(choices.at("preset"), "--set preset=tiny");
  EXPECT_EQ(choices.at("world_model.deter"), "--set agent.world_model.deter=64");
  EXPECT_EQ(choices.at("world_model.image"), "preset 'tiny'");
  EXPECT_FALSE(choices.contains("phase"));
}

// The backward's schedule differs by preset (parts side by side on tiny, op by op on cpu) and
// a run may choose it.
TEST(ServiceConfigTest, BackwardScheduleFollowsThePresetUnlessSet) {
  testing::TempDir dir;
  EXPECT_FALSE(ServiceConfig::resolve({.run_dir = dir.path() / "r"}).agent().backward_parts);
  EXPECT_TRUE(ServiceConfig::resolve({.run_dir = dir.path() / "r", .overrides = {"preset=tiny"}})
                  .agent()
                  .backward_parts);
  EXPECT_FALSE(ServiceConfig::resolve({.run_dir = dir.path() / "r",
                                       .overrides = {"preset=tiny", "agent.backward_parts=false"}})
                   .agent()
                   .backward_parts);
  EXPECT_TRUE(ServiceConfig::resolve({.run_dir = dir.path() / "r",
                                      .overrides = {"preset=cpu", "agent.backward_parts=true"}})
                  .agent()
                  .backward_parts);
}

// Few-shot keeps the world model frozen, continuation head included, unless a run asks for the
// ablation; a value that is not a boolean is refused.
TEST(ServiceConfigTest, FinetuneContIsOffUnlessSet) {
  testing::TempDir dir;
  EXPECT_FALSE(ServiceConfig::resolve({.run_dir = dir.path() / "r", .overrides = {"preset=tiny"}})
                   .agent()
                   .finetune_cont);
  EXPECT_TRUE(ServiceConfig::resolve({.run_dir = dir.path() / "r",
                                      .overrides = {"preset=tiny", "agent.finetune_cont=true"}})
                  .agent()
                  .finetune_cont);
  EXPECT_ANY_THROW(ServiceConfig::resolve(
      {.run_dir = dir.path() / "r", .overrides = {"agent.finetune_cont=sometimes"}}));
}

TEST(ServiceConfigTest, DdsSecurityFlagNamesTheFolder) {
  testing::TempDir dir;
  const auto off = ServiceConfig::resolve({.run_dir = dir.path() / "r"});
  EXPECT_EQ(off.config().get<std::string>("dds.security_dir"), "") << "security is opt-in";
  const auto on = ServiceConfig::resolve({.run_dir = dir.path() / "r",
                                          .dds_security = "runs/r/security",
                                          .overrides = {"dds.security_role=observer"}});
  EXPECT_EQ(on.config().get<std::string>("dds.security_dir"), "runs/r/security");
  EXPECT_EQ(on.config().origin("dds.security_dir"), "--dds-security");
  EXPECT_EQ(on.config().get<std::string>("dds.security_role"), "observer");
}

TEST(ServiceConfigTest, TaskPhasesReachTheWirePhase) {
  testing::TempDir dir;
  const auto config = ServiceConfig::resolve(
      {.run_dir = dir.path() / "r",
       .overrides = {"agent.phase=finetune", "agent.task=collision_avoidance"}});
  EXPECT_EQ(config.agent().task, "collision_avoidance");
  EXPECT_EQ(config.wire_phase(), msg::PHASE_FINETUNE);
}

TEST(ServiceConfigTest, MistakesThrowWithTheKeyNamed) {
  testing::TempDir dir;
  try {
    ServiceConfig::resolve({.run_dir = dir.path() / "r", .overrides = {"learner.replay_ration=3"}});
    FAIL() << "an unknown key must throw";
  } catch (const config::ConfigError& error) {
    EXPECT_NE(std::string(error.what()).find("learner.replay_ratio"), std::string::npos)
        << error.what();
  }
  EXPECT_THROW(ServiceConfig::resolve(
                   {.run_dir = dir.path() / "r", .overrides = {"agent.world_model.image=33"}}),
               agent::AgentConfigError);
  EXPECT_THROW(ServiceConfig::resolve({}), config::ConfigError);
}

TEST(ServiceConfigTest, ArchitectureDescriptorTellsPresetsAndActorsApart) {
  const auto tiny = agent::preset("tiny");
  auto finetune = tiny;
  finetune.phase = agent::Phase::kFinetune;
  EXPECT_NE(architecture_descriptor(tiny), architecture_descriptor(agent::preset("cpu")));
  EXPECT_NE(architecture_descriptor(tiny), architecture_descriptor(finetune));
  EXPECT_EQ(architecture_descriptor(tiny), architecture_descriptor(agent::preset("tiny")));
}

// Every shipped config must resolve, so a renamed key cannot silently break a recipe.
TEST(ServiceConfigTest, EveryShippedConfigResolves) {
  testing::TempDir dir;
  const auto files = testing::shipped_configs();
  EXPECT_GE(files.size(), 8u);
  for (const auto& file : files) {
    SCOPED_TRACE(file.filename().string());
    const auto config = ServiceConfig::resolve({.config_file = file, .run_dir = dir.path() / "r"});
    EXPECT_NO_THROW(config.agent());
  }
}

}  // namespace
}  // namespace indrive::service
