#include "indrive/agent/agent_config.h"

#include <gtest/gtest.h>

#include <string>

namespace indrive::agent {
namespace {

TEST(AgentConfig, PresetsSetTheSizesOfTheTable) {
  const AgentConfig tiny = preset("tiny");
  EXPECT_EQ(tiny.world_model.image, 32);
  EXPECT_EQ(tiny.world_model.cnn_depth, 8);
  EXPECT_EQ(tiny.world_model.deter, 128);
  EXPECT_EQ(tiny.world_model.units, 128);
  EXPECT_EQ(tiny.world_model.stoch_dim(), 256);
  EXPECT_EQ(tiny.replay.batch, 8);
  EXPECT_EQ(tiny.replay.length, 16);
  const AgentConfig small = preset("small");
  EXPECT_EQ(small.world_model.image, 128);
  EXPECT_EQ(small.world_model.deter, 512);
  EXPECT_EQ(small.world_model.feat_dim(), 512 + 1024);
  EXPECT_EQ(preset("cpu").world_model.image, 64);
  for (const char* name : {"tiny", "cpu", "small"}) EXPECT_NO_THROW(validate(preset(name)));
}

TEST(AgentConfig, DefaultsAreThePapersValues) {
  const AgentConfig c = preset("cpu");
  EXPECT_EQ(c.intrinsic.method, Method::kDisag);
  EXPECT_EQ(c.intrinsic.ensemble, 8);
  EXPECT_EQ(c.intrinsic.disag_reward, DisagReward::kVariance);
  EXPECT_FLOAT_EQ(c.intrinsic.norm_eps, 1.0f);
  EXPECT_EQ(c.behavior.horizon, 15);
  EXPECT_FLOAT_EQ(c.behavior.gamma, 0.99f);
  EXPECT_FLOAT_EQ(c.behavior.lambda, 0.95f);
  EXPECT_FLOAT_EQ(c.behavior.entropy, 3e-4f);
  EXPECT_FLOAT_EQ(c.behavior.slow_critic_rate, 0.02f);
  EXPECT_FLOAT_EQ(c.world_model.kl_dyn, 0.5f);
  EXPECT_FLOAT_EQ(c.world_model.kl_rep, 0.1f);
  EXPECT_FLOAT_EQ(c.world_model.free_nats, 1.0f);
  EXPECT_FLOAT_EQ(c.world_model.unimix, 0.01f);
  EXPECT_EQ(c.replay.capacity, 100000);
  EXPECT_EQ(c.replay.prefill, 1000);
}

// The two few-shot ablations overlap (the whole world model includes the continuation head),
// so a config that sets both is refused with a message that says which to unset.
// The names results files give a run's method and task.
TEST(AgentConfig, MethodAndTaskLabelsAsResultsFilesWriteThem) {
  AgentConfig config = preset("tiny");
  config.phase = Phase::kPretrain;
  config.intrinsic.method = Method::kIcm;
  config.task = "lane_following";
  EXPECT_EQ(method_label(config), "icm");
  EXPECT_EQ(task_label(config), "exploration");
  config.phase = Phase::kFinetune;
  EXPECT_EQ(task_label(config), "lane_following");
  config.phase = Phase::kDreamer;
  config.task = "collision_avoidance";
  EXPECT_EQ(method_label(config), "dreamer");
  EXPECT_EQ(task_label(config), "collision_avoidance");
}

TEST(AgentConfig, FinetuneWorldModelExcludesFinetuneCont) {
  AgentConfig c = preset("tiny");
  EXPECT_FALSE(c.finetune_world_model);
  set_config_value(c, "finetune_world_model", "true");
  EXPECT_TRUE(c.finetune_world_model);
  EXPECT_NO_THROW(validate(c));
  c.finetune_cont = true;
  try {
    validate(c);
    FAIL() << "both few-shot ablations accepted";
  } catch (const AgentConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("set finetune_cont to false"), std::string::npos)
        << e.what();
  }
}

TEST(AgentConfig, KeysRoundTripThroughText) {
  AgentConfig c = preset("tiny");
  set_config_value(c, "intrinsic.method", "rnd");
  set_config_value(c, "behavior.horizon", "7");
  set_config_value(c, "world_model.kl_dyn", "0.25");
  set_config_value(c, "phase", "finetune");
  set_config_value(c, "intrinsic.disag_reward", "std");
  EXPECT_EQ(c.intrinsic.method, Method::kRnd);
  EXPECT_EQ(c.behavior.horizon, 7);
  EXPECT_FLOAT_EQ(c.world_model.kl_dyn, 0.25f);
  EXPECT_EQ(c.phase, Phase::kFinetune);
  AgentConfig copy = preset("cpu");
  for (const auto& [key, value] : config_values(c)) set_config_value(copy, key, value);
  EXPECT_EQ(config_values(copy), config_values(c));
}

TEST(AgentConfig, BadInputThrowsTypedErrors) {
  EXPECT_THROW(preset("huge"), AgentConfigError);
  AgentConfig c = preset("tiny");
  EXPECT_THROW(set_config_value(c, "world_model.nope", "1"), AgentConfigError);
  EXPECT_THROW(set_config_value(c, "behavior.horizon", "fifteen"), AgentConfigError);
  EXPECT_THROW(set_config_value(c, "behavior.horizon", "15x"), AgentConfigError);
  EXPECT_THROW(set_config_value(c, "intrinsic.method", "curiosity"), AgentConfigError);
  set_config_value(c, "world_model.image", "48");
  EXPECT_THROW(validate(c), AgentConfigError);
  // The disagreement ensemble makes its members' first hidden products as one GEMM: a config
  // without a hidden layer is refused by name, not left to fail inside the module.
  AgentConfig no_hidden = preset("tiny");
  set_config_value(no_hidden, "intrinsic.layers", "0");
  try {
    validate(no_hidden);
    ADD_FAILURE() << "intrinsic.layers 0 with disag was accepted";
  } catch (const AgentConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("intrinsic.layers"), std::string::npos) << e.what();
  }
  set_config_value(no_hidden, "intrinsic.method", "rnd");
  EXPECT_NO_THROW(validate(no_hidden)) << "RND's networks may have no hidden layer";
  try {
    preset("huge");
  } catch (const AgentConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("tiny, cpu, small"), std::string::npos);
  }
}

}  // namespace
}  // namespace indrive::agent
