#include "indrive/basics/config.h"

#include <gtest/gtest.h>

#include <fstream>

#include "testing.h"

namespace indrive::config {
namespace {

// A toy schema in the shape the agent's will have.
Schema toy_schema() {
  Schema schema;
  schema.add_int("replay.capacity", 100000, "env steps kept in replay", 1, 100000000)
      .add_int("train.batch_size", 16, "sequences per batch", 1, 1024)
      .add_float("train.learning_rate", 1e-4, "world-model learning rate", 0.0, 1.0)
      .add_bool("train.async", false, "run without the replay-ratio limit")
      .add_string("run.id", "", "run directory name; empty: a timestamp")
      .add_choice("agent.method", "disag", {"disag", "icm", "rnd"}, "intrinsic module")
      .add_number_list("env.densities", {5, 10, 20}, "traffic densities to resample", 0, 500);
  schema.add_preset("toy", {{"replay.capacity", "1000"}, {"train.batch_size", "4"}},
                    "a tiny preset for tests");
  schema.add_int("dds.domain_id", 0, "DDS domain", 0, 232)
      .add_string("dds.profiles_file", "", "Fast DDS XML profiles")
      .add_string("dds.security_dir", "", "DDS Security folder");
  return schema;
}

std::string error_of(const Schema& schema, std::string_view yaml,
                     std::vector<std::string> overrides = {}) {
  try {
    Config::resolve_text(schema, yaml, "config file run.yaml", {.overrides = std::move(overrides)});
  } catch (const ConfigError& error) {
    return error.what();
  }
  return "(no ConfigError)";
}

TEST(Config, DefaultsPresetFileAndOverridesApplyInOrder) {
  const Schema schema = toy_schema();
  const Config defaults = Config::resolve(schema, {});
  EXPECT_EQ(defaults.get<int>("replay.capacity"), 100000);
  EXPECT_EQ(defaults.get<std::string>("agent.method"), "disag");
  EXPECT_EQ(defaults.get<std::vector<double>>("env.densities"), (std::vector<double>{5, 10, 20}));

  // The preset sets capacity and batch; the file overrides batch; --set overrides the file.
  const Config config = Config::resolve_text(
      schema, "train:\n  batch_size: 8\n  learning_rate: 3e-4\nagent.method: icm\n", "run.yaml",
      {.preset = "toy", .overrides = {"train.batch_size=2", "env.densities=[5, 7.5]"}});
  EXPECT_EQ(config.preset(), "toy");
  EXPECT_EQ(config.get<int>("replay.capacity"), 1000);
  EXPECT_EQ(config.get<int>("train.batch_size"), 2);
  EXPECT_DOUBLE_EQ(config.get<double>("train.learning_rate"), 3e-4);
  EXPECT_FLOAT_EQ(config.get<float>("train.learning_rate"), 3e-4f);
  EXPECT_EQ(config.get<std::string>("agent.method"), "icm");
  EXPECT_EQ(config.get<std::vector<double>>("env.densities"), (std::vector<double>{5, 7.5}));
  EXPECT_EQ(config.get<bool>("train.async"), false);
}

TEST(Config, EveryValueKnowsWhereItCameFrom) {
  const Schema schema = toy_schema();
  const Config defaults = Config::resolve(schema, {});
  EXPECT_EQ(defaults.origin("replay.capacity"), "");
  EXPECT_EQ(defaults.preset_origin(), "");

  const Config config =
      Config::resolve_text(schema, "train:\n  batch_size: 8\nenv.densities: [5]\n", "run.yaml",
                           {.overrides = {"preset=toy", "agent.method=icm"}});
  EXPECT_EQ(config.preset_origin(), "--set preset=toy");
  EXPECT_EQ(config.origin("replay.capacity"), "preset 'toy'");
  EXPECT_EQ(config.origin("train.batch_size"), "run.yaml line 2");
  EXPECT_EQ(config.origin("env.densities"), "run.yaml line 3");
  EXPECT_EQ(config.origin("agent.method"), "--set agent.method=icm");
  EXPECT_EQ(config.origin("train.async"), "") << "a default has no origin";
}

TEST(Config, PresetCanBeNamedInTheFile) {
  const Schema schema = toy_schema();
  const Config config =
      Config::resolve_text(schema, "preset: toy\ntrain:\n  batch_size: 8\n", "run.yaml");
  EXPECT_EQ(config.preset(), "toy");
  EXPECT_EQ(config.get<int>("replay.capacity"), 1000);
  EXPECT_EQ(config.get<int>("train.batch_size"), 8) << "the file applies after the preset";
  const std::string message = error_of(schema, "preset: huge\n");
  EXPECT_NE(message.find("unknown preset 'huge'; known presets: toy"), std::string::npos)
      << message;
}

TEST(Config, UnknownKeySuggestsClosest) {
  const Schema schema = toy_schema();
  const std::string message = error_of(schema, "replay:\n  capacty: 5\n");
  EXPECT_NE(message.find("config file run.yaml line 2: key 'replay.capacty': unknown key; did "
                         "you mean 'replay.capacity'?"),
            std::string::npos)
      << message;
  const std::string far = error_of(schema, "", {"train.zzzzzzzzzzzz=1"});
  EXPECT_NE(far.find("keys under 'train.' are: train.async, train.batch_size"), std::string::npos)
      << far;
}

// Found by tests/fuzz (target config): a list as a key escaped as a yaml-cpp exception.
TEST(Config, AKeyThatIsNotAPlainNameIsAConfigError) {
  const Schema schema = toy_schema();
  const std::string message = error_of(schema, "? [replay, capacity]\n: 5\n");
  EXPECT_NE(message.find("a key must be a plain name"), std::string::npos) << message;
  const std::string nested = error_of(schema, "train:\n  ? {a: 1}\n  : 2\n");
  EXPECT_NE(nested.find("a key must be a plain name"), std::string::npos) << nested;
}

TEST(Config, WrongTypeNamesKeyAndExpectedType) {
  const Schema schema = toy_schema();
  std::string message = error_of(schema, "replay:\n  capacity: lots\n");
  EXPECT_NE(message.find("line 2: key 'replay.capacity': expected an integer, got 'lots'"),
            std::string::npos)
      << message;
  message = error_of(schema, "train:\n  async: maybe\n");
  EXPECT_NE(message.find("key 'train.async': expected true or false, got 'maybe'"),
            std::string::npos)
      << message;
  message = error_of(schema, "replay: 5\n");
  EXPECT_NE(message.find("key 'replay': unknown key"), std::string::npos) << message;
  message = error_of(schema, "train:\n  batch_size: [1, 2]\n");
  EXPECT_NE(message.find("key 'train.batch_size': expected a integer, got a list"),
            std::string::npos)
      << message;
  message = error_of(schema, "env:\n  densities: [5, x]\n");
  EXPECT_NE(message.find("'x' is not a number"), std::string::npos) << message;
  // Reading a key as the wrong C++ type is a bug in the caller, reported the same way.
  const Config config = Config::resolve(schema, {});
  EXPECT_THROW(config.get<std::string>("replay.capacity"), ConfigError);
  EXPECT_THROW(config.get<int>("replay.nothing"), ConfigError);
}

TEST(Config, OutOfRangeAndBadChoiceSayWhatIsAllowed) {
  const Schema schema = toy_schema();
  std::string message = error_of(schema, "", {"replay.capacity=0"});
  EXPECT_NE(message.find("--set replay.capacity=0: key 'replay.capacity': out of range: 0 is not "
                         "in [1, 100000000]"),
            std::string::npos)
      << message;
  message = error_of(schema, "train:\n  learning_rate: 2.5\n");
  EXPECT_NE(message.find("out of range: 2.5 is not in [0, 1]"), std::string::npos) << message;
  message = error_of(schema, "", {"env.densities=5,600"});
  EXPECT_NE(message.find("out of range: 600 is not in [0, 500]"), std::string::npos) << message;
  message = error_of(schema, "agent:\n  method: curiosity\n");
  EXPECT_NE(message.find("key 'agent.method': 'curiosity' is not one of the choices: disag, "
                         "icm, rnd"),
            std::string::npos)
      << message;
}

TEST(Config, MalformedOverridesAndYamlAreReported) {
  const Schema schema = toy_schema();
  std::string message = error_of(schema, "", {"replay.capacity"});
  EXPECT_NE(message.find("--set replay.capacity: malformed override; write --set key=value"),
            std::string::npos)
      << message;
  message = error_of(schema, "", {"=3"});
  EXPECT_NE(message.find("the key before '=' is empty"), std::string::npos) << message;
  message = error_of(schema, "train:\n  batch_size: 4\n   bad: [1, 2\n");
  EXPECT_NE(message.find("config file run.yaml line 3: YAML syntax error"), std::string::npos)
      << message;
  message = error_of(schema, "- just\n- a list\n");
  EXPECT_NE(message.find("expected a map of keys at the top level"), std::string::npos) << message;
  EXPECT_THROW(Config::resolve(schema, {.file = "/nonexistent/run.yaml"}), ConfigError);
}

TEST(Config, IntegersAcceptExactScientificNotation) {
  const Schema schema = toy_schema();
  EXPECT_EQ(
      Config::resolve(schema, {.overrides = {"replay.capacity=1e5"}}).get<int>("replay.capacity"),
      100000);
  const std::string message = error_of(schema, "", {"replay.capacity=1.5"});
  EXPECT_NE(message.find("expected an integer, got '1.5'"), std::string::npos) << message;
}

TEST(Config, ResolvedYamlRoundTripsExactly) {
  Schema schema = toy_schema();
  schema.add_string("run.note", "", "free text");
  const Config config = Config::resolve_text(
      schema, "", "none",
      {.preset = "toy",
       .overrides = {"train.learning_rate=0.1", "run.id=2026-11-23 run: #1", "run.note=true",
                     "env.densities=[]", "train.async=yes", "dds.domain_id=42"}});
  testing::TempDir dir;
  const auto path = dir.path() / "config.yaml";
  config.write_yaml(path);
  const Config reread = Config::resolve(schema, {.file = path});
  EXPECT_EQ(reread, config) << config.to_yaml();
  EXPECT_EQ(reread.to_yaml(), config.to_yaml());
  EXPECT_DOUBLE_EQ(reread.get<double>("train.learning_rate"), 0.1);
  EXPECT_EQ(reread.get<std::string>("run.id"), "2026-11-23 run: #1");
  EXPECT_EQ(reread.get<std::string>("run.note"), "true");
  EXPECT_TRUE(reread.get<std::vector<double>>("env.densities").empty());
  EXPECT_EQ(reread.get<int>("dds.domain_id"), 42);
  EXPECT_NE(config.to_yaml().find("preset: toy"), std::string::npos);
}

TEST(Config, CommandLineFlagsBecomeSources) {
  const char* argv[] = {"learner",
                        "--config",
                        "run.yaml",
                        "--set",
                        "train.batch_size=4",
                        "--preset=toy",
                        "actor",
                        "--dds-profiles",
                        "x.xml",
                        "--dds-security",
                        "sec",
                        "--set=a.b=1",
                        "-h"};
  const CommandLine line = parse_command_line(
      static_cast<int>(std::size(argv)), argv,
      {{"--dds-profiles", "dds.profiles_file"}, {"--dds-security", "dds.security_dir"}});
  EXPECT_EQ(line.sources.file, "run.yaml");
  EXPECT_EQ(line.sources.preset, "toy");
  EXPECT_EQ(line.sources.overrides,
            (std::vector<std::string>{"train.batch_size=4", "dds.profiles_file=x.xml",
                                      "dds.security_dir=sec", "a.b=1"}));
  EXPECT_EQ(line.rest, (std::vector<std::string>{"actor"}));
  EXPECT_TRUE(line.help);
  const char* missing[] = {"learner", "--set"};
  EXPECT_THROW(parse_command_line(2, missing), ConfigError);
}

TEST(Config, DescribeListsKeysAndPresets) {
  const std::string text = toy_schema().describe();
  EXPECT_NE(text.find("agent.method (choice, default disag, one of disag|icm|rnd): intrinsic "
                      "module"),
            std::string::npos)
      << text;
  EXPECT_NE(text.find("preset toy: a tiny preset for tests"), std::string::npos) << text;
}

}  // namespace
}  // namespace indrive::config
