// Tests of the evaluator's inputs and policy sources: names checked against what exists,
// snapshot files and heads, the step budget, and the oracle's test for a vehicle ahead.
#include "indrive/actor/eval_policy.h"

#include <gtest/gtest.h>

#include <cstring>
#include <fstream>
#include <numbers>

#include "indrive/common/agent/agent.h"
#include "indrive/common/agent/policy.h"
#include "indrive/common/checksum.h"
#include "indrive/common/nn/serialize.h"
#include "indrive/envserver/town.h"
#include "testing.h"

namespace indrive::actor {
namespace {

// The message of the EvalError `body` throws ("" when it throws nothing).
template <typename F>
std::string eval_error_of(F&& body) {
  try {
    body();
  } catch (const EvalError& error) {
    return error.what();
  }
  return "";
}

std::vector<std::uint8_t> tiny_snapshot(agent::Phase phase) {
  agent::AgentConfig config = agent::preset("tiny");
  config.phase = phase;
  agent::Agent agent(config);
  return agent.snapshot();
}

TEST(EvalPolicy, PolicySourceAndHeadNamesAreCheckedWithTheAllowedValues) {
  EXPECT_EQ(parse_policy_source("oracle"), PolicySource::kOracle);
  EXPECT_EQ(parse_policy_source("random"), PolicySource::kRandom);
  EXPECT_EQ(parse_policy_source("snapshot"), PolicySource::kSnapshot);
  const std::string message = eval_error_of([] { parse_policy_source("scripted"); });
  EXPECT_NE(message.find("'scripted'"), std::string::npos) << message;
  EXPECT_NE(message.find("oracle"), std::string::npos) << message;

  EXPECT_EQ(resolve_head("auto", "zero_shot"), PolicyHead::kExploration);
  EXPECT_EQ(resolve_head("auto", "few_shot"), PolicyHead::kTask);
  EXPECT_EQ(resolve_head("task", "zero_shot"), PolicyHead::kTask);
  EXPECT_NE(eval_error_of([] { resolve_head("critic", "zero_shot"); }).find("'critic'"),
            std::string::npos);
}

TEST(EvalPolicy, UnknownTownOrRouteNamesTheValueAndWhatExists) {
  ProtocolGrid grid{.towns = {"town01", "town99"}, .routes = {"straight"}};
  std::string message = eval_error_of([&] { check_grid_names(grid); });
  EXPECT_NE(message.find("'town99'"), std::string::npos) << message;
  EXPECT_NE(message.find("town01, town02"), std::string::npos) << message;

  grid = {.towns = {"town02"}, .routes = {"straight", "figure_eight"}};
  message = eval_error_of([&] { check_grid_names(grid); });
  EXPECT_NE(message.find("'figure_eight'"), std::string::npos) << message;
  EXPECT_NE(message.find("straight, right_loop, left_loop, two_turn"), std::string::npos)
      << message;

  grid = {.towns = {"town01", "town02", "grid:3"}};
  EXPECT_NO_THROW(check_grid_names(grid));
}

TEST(EvalPolicy, SnapshotGroupsAreReadWithoutLoading) {
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

TEST(EvalPolicy, SnapshotMissingTheRequestedHeadIsAClearError) {
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

TEST(EvalPolicy, SnapshotOfAnotherPresetNamesThePreset) {
  const auto pretrain = tiny_snapshot(agent::Phase::kPretrain);
  const std::string message = eval_error_of([&] {
    make_snapshot_policy(agent::preset("cpu"), pretrain, PolicyHead::kExploration, "file f");
  });
  EXPECT_NE(message.find("file f does not fit the configured model (preset cpu)"),
            std::string::npos)
      << message;
}

TEST(EvalPolicy, SnapshotFilesRoundTripAndBadFilesAreNamed) {
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

// A format-1 file built by hand from its parts, as eval_policy.h documents the format.
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

TEST(EvalPolicy, TinySnapshotFileEvaluatesWithTheDefaultConfig) {
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

TEST(EvalPolicy, ChosenSizesThatDifferFromTheFileAreAClearError) {
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

TEST(EvalPolicy, SnapshotFileWithoutHeaderStillLoadsWithItsPreset) {
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

TEST(EvalPolicy, TruncatedOrFlippedHeaderIsRejectedWithAMessage) {
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

TEST(EvalPolicy, StepBudgetIsFiveStepsPerMetreByDefault) {
  EXPECT_EQ(route_step_budget(649.0), 3245);  // town01's longest loop
  EXPECT_EQ(route_step_budget(200.0), 1000);
  EXPECT_EQ(route_step_budget(100.0, 5.0, 1.0), 200);
  EXPECT_EQ(route_step_budget(0.0), 1);
  // The budget at the oracle's 5 m/s leaves the 1.5x slack of the 3 m/s task speed and more.
  EXPECT_GT(route_step_budget(649.0), 649.0 / (5.0 * 0.1) * 2.0);
}

TEST(EvalPolicy, RouteCompletionIsWholeAtTheDestination) {
  // The destination fires within 10 m of the terminal waypoint: that is the whole route.
  EXPECT_DOUBLE_EQ(route_completion(275.0, 283.0, env::kDestination), 1.0);
  EXPECT_DOUBLE_EQ(route_completion(141.5, 283.0, env::kOffRoute), 0.5);
  EXPECT_DOUBLE_EQ(route_completion(-3.0, 283.0, env::kCollision), 0.0);
  EXPECT_DOUBLE_EQ(route_completion(700.0, 649.0, env::kTimeLimit), 1.0);
  EXPECT_DOUBLE_EQ(route_completion(5.0, 0.0, env::kStall), 0.0);
}

TEST(EvalPolicy, ProtocolRecordSucceedsOnlyAtTheDestinationWithoutFailures) {
  const EpisodeSpec spec{.town = "town02",
                         .route = "two_turn",
                         .density = 10,
                         .episode = 4,
                         .traffic_seed = 202,
                         .spawn_seed = 33};
  const EpisodeRecord reached = protocol_record(spec, env::kDestination, 812, 1.0, 3.5);
  EXPECT_TRUE(reached.success);
  EXPECT_EQ(reached.failure_reason, "");
  EXPECT_EQ(reached.town, "town02");
  EXPECT_EQ(reached.route, "two_turn");
  EXPECT_EQ(reached.density, 10);
  EXPECT_EQ(reached.traffic_seed, 202);
  EXPECT_EQ(reached.spawn_seed, 33);
  EXPECT_EQ(reached.episode, 4);
  EXPECT_EQ(reached.steps, 812);
  EXPECT_DOUBLE_EQ(reached.route_completion, 1.0);
  EXPECT_DOUBLE_EQ(reached.episode_return, 3.5);
  // Reaching the destination while colliding is a failure named by the failure event.
  const EpisodeRecord crashed =
      protocol_record(spec, env::kDestination | env::kCollision, 812, 1.0, 0.0);
  EXPECT_FALSE(crashed.success);
  EXPECT_EQ(crashed.failure_reason, env::event_names(env::kCollision));
  const EpisodeRecord timed_out = protocol_record(spec, env::kTimeLimit, 3245, 0.4, 0.0);
  EXPECT_FALSE(timed_out.success);
  EXPECT_EQ(timed_out.failure_reason, env::event_names(env::kTimeLimit));
  // Leaving the route is a failure of its own.
  const EpisodeRecord strayed = protocol_record(spec, env::kOffRoute, 300, 0.2, 0.0);
  EXPECT_FALSE(strayed.success);
  EXPECT_EQ(strayed.failure_reason, "off_route");
}

TEST(EvalPolicy, LeaderAheadSeesOnlyVehiclesOnTheRouteInFront) {
  const env::Town town = env::load_town("town01");
  const env::Route& route = env::find_route(town.routes, "right_loop");
  auto box_at = [&](double s_m, double lateral_m) {
    const env::Pose2 pose = route.pose_at(s_m);
    env::Box box;
    box.pose = {pose.x_m - lateral_m * std::sin(pose.yaw_rad),
                pose.y_m + lateral_m * std::cos(pose.yaw_rad), pose.yaw_rad};
    return box;
  };
  const double ego_s = 50.0;
  const std::vector<env::Box> ahead = {box_at(ego_s + 12.0, 0.3)};
  EXPECT_TRUE(leader_ahead(route, ego_s, ahead, 20.0, 2.2));
  const std::vector<env::Box> far = {box_at(ego_s + 35.0, 0.0)};
  EXPECT_FALSE(leader_ahead(route, ego_s, far, 20.0, 2.2));
  const std::vector<env::Box> behind = {box_at(ego_s - 8.0, 0.0)};
  EXPECT_FALSE(leader_ahead(route, ego_s, behind, 20.0, 2.2));
  // Oncoming traffic in the next lane (3.5 m to the left) is not a leader.
  const std::vector<env::Box> oncoming = {box_at(ego_s + 10.0, 3.5)};
  EXPECT_FALSE(leader_ahead(route, ego_s, oncoming, 20.0, 2.2));
  // On a loop, "ahead" wraps past the start.
  const std::vector<env::Box> wrapped = {box_at(5.0, 0.0)};
  EXPECT_TRUE(leader_ahead(route, route.length_m() - 6.0, wrapped, 20.0, 2.2));
}

// A car ahead to the left, oncoming and starting a left turn into the ego's lane: a straight
// line keeps it 6 m to the side, its turn rate brings it across the ego's path.
TEST(EvalPolicy, ConflictAheadFollowsATurningCarAlongItsTurn) {
  const env::Town town = env::load_town("town01");
  const env::Route& route = env::find_route(town.routes, "right_loop");
  const double ego_s = 50.0;
  const env::Pose2 ego_pose = route.pose_at(ego_s);
  // The test needs a straight stretch ahead of the ego.
  ASSERT_NEAR(env::wrap_angle(route.pose_at(ego_s + 20.0).yaw_rad - ego_pose.yaw_rad), 0.0, 0.05);
  const env::Box ego{env::SemanticClass::kVehicle, ego_pose, 4.8, 2.1, 1.5};
  const double c = std::cos(ego_pose.yaw_rad), s = std::sin(ego_pose.yaw_rad);
  auto world = [&](double forward, double left) {
    return Eigen::Vector2d(ego_pose.x_m + forward * c - left * s,
                           ego_pose.y_m + forward * s + left * c);
  };
  const Eigen::Vector2d at = world(20.0, 6.0);
  const double heading = ego_pose.yaw_rad + std::numbers::pi;  // oncoming
  const std::vector<env::Box> others = {
      {env::SemanticClass::kVehicle, {at.x(), at.y(), heading}, 4.8, 2.1, 1.5}};
  const std::vector<Eigen::Vector2d> velocity = {
      5.0 * Eigen::Vector2d(std::cos(heading), std::sin(heading))};
  const OracleOptions options;
  EXPECT_FALSE(conflict_ahead(route, ego, ego_s, 5.0, others, velocity, options));
  const std::vector<double> straight = {0.0};
  EXPECT_FALSE(conflict_ahead(route, ego, ego_s, 5.0, others, velocity, options, straight));
  const std::vector<double> turning_left = {0.5};  // rad/s, a 10 m radius at 5 m/s
  EXPECT_TRUE(conflict_ahead(route, ego, ego_s, 5.0, others, velocity, options, turning_left));
  // Turning right it leaves the ego's road.
  const std::vector<double> turning_right = {-0.5};
  EXPECT_FALSE(conflict_ahead(route, ego, ego_s, 5.0, others, velocity, options, turning_right));
}

TEST(EvalPolicy, FollowerBehindIsACarCloseBehindInLine) {
  const env::Box ego{
      env::SemanticClass::kVehicle, {10.0, 5.0, std::numbers::pi / 2}, 4.8, 2.1, 1.5};
  auto box_at = [](double x, double y) {
    return std::vector<env::Box>{{env::SemanticClass::kVehicle, {x, y, 0.0}, 4.8, 2.1, 1.5}};
  };
  // The ego faces +y: behind is -y.
  EXPECT_TRUE(follower_behind(ego, box_at(10.5, -3.0), 15.0));
  EXPECT_FALSE(follower_behind(ego, box_at(10.0, -12.0), 15.0));  // 17 m back
  EXPECT_FALSE(follower_behind(ego, box_at(14.0, -3.0), 15.0));   // the next lane over
  EXPECT_FALSE(follower_behind(ego, box_at(10.0, 12.0), 15.0));   // ahead
}

// The grid's route names must mean what they say: `indrive-env routes` once printed "2 turns"
// for `straight`, counting the junctions it crosses; it crosses them without turning.
TEST(EvalPolicy, BuiltInStraightRoutesCrossJunctionsWithoutTurning) {
  for (const char* name : {"town01", "town02"}) {
    const env::Town town = env::load_town(name);
    const env::Route& straight = env::find_route(town.routes, "straight");
    EXPECT_FALSE(straight.is_loop()) << name;
    EXPECT_FALSE(straight.turns().empty()) << name;
    for (const env::TurnDirection turn : straight.turns()) {
      EXPECT_EQ(turn, env::TurnDirection::kStraight) << name;
    }
  }
}

}  // namespace
}  // namespace indrive::actor
