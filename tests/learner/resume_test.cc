// A learner resumes from the newest checkpoint that restores completely: a damaged newer one
// (truncated, a bit flipped in its counters line or in its replay section, an agent section
// that does not load) is skipped with a warning and set aside, and with none intact the
// learner refuses to start. The checkpoints are real (a tiny agent and a replay buffer packed
// like the learner packs them) and the Learner is the real one, in this process.
#include <gtest/gtest.h>

#include <fstream>
#include <mutex>
#include <nlohmann/json.hpp>
#include <optional>

#include "indrive/agent/agent.h"
#include "indrive/basics/log.h"
#include "indrive/basics/run_dir.h"
#include "indrive/learner/learner.h"
#include "testing.h"

namespace indrive::learner {
namespace {

namespace fs = std::filesystem;

class LearnerResumeTest : public ::testing::Test {
 protected:
  void SetUp() override {
    const fs::path config_file = dir_.path() / "resume.yaml";
    std::ofstream(config_file) << "preset: tiny\nlearner:\n  checkpoint_keep: 5\n";
    service_.emplace(service::ServiceConfig::resolve(
        {.config_file = config_file,
         .run_dir = dir_.path() / "runs" / "rtest",
         .domain_id = indrive::testing::unique_domain_id(),
         .dds_profile = indrive::testing::source_path("deploy/dds/single_host.xml").string()}));
    agent_bytes_ = agent::Agent(service_->agent()).checkpoint_bytes();
    log::set_sink([this](const log::Record& record) {
      if (record.category != "learner") return;
      std::lock_guard<std::mutex> lock(log_mutex_);
      log_ += std::string(log::level_name(record.level)) + " " + std::string(record.message) + "\n";
    });
  }
  void TearDown() override { log::set_sink({}); }

  fs::path checkpoints() const { return service_->run_dir() / "checkpoints"; }

  // Checkpoint k of the run: 100 k env steps, 10 k updates, policy v k and 16 k replay steps
  // (none with `with_replay` false), with `agent_bytes` in place of a good agent when given.
  fs::path write_checkpoint(int k, bool with_replay = true,
                            std::optional<std::vector<std::uint8_t>> agent_bytes = {}) {
    const agent::AgentConfig config = service_->agent();
    agent::ReplayBuffer replay({.capacity = config.replay.capacity,
                                .height = config.world_model.image,
                                .width = config.world_model.image});
    const int steps = with_replay ? 16 * k : 0;
    for (int i = 0; i < steps; ++i) {
      agent::ReplayStep step;
      step.frame.assign(static_cast<std::size_t>(config.world_model.image) *
                            static_cast<std::size_t>(config.world_model.image),
                        static_cast<std::uint8_t>((i + k) % 8));
      step.action = i % 9;
      step.is_first = i == 0;
      replay.add(0, step);
    }
    const LearnerCounters counters{.env_steps = 100 * k,
                                   .updates = 10 * k,
                                   .policy_version = static_cast<std::uint64_t>(k),
                                   .learner_epoch = 1};
    const auto replay_bytes = with_replay ? replay.to_bytes() : std::vector<std::uint8_t>{};
    return CheckpointFiles(checkpoints(), 5)
        .save(static_cast<std::uint64_t>(counters.updates),
              pack_checkpoint(counters, agent_bytes.value_or(agent_bytes_), replay_bytes));
  }

  std::string log() {
    std::lock_guard<std::mutex> lock(log_mutex_);
    return log_;
  }

  // Resumes a learner, checks that it continued checkpoint k with `skipped` newer ones set
  // aside, and prints the figures.
  void expect_resumed_from(int k, std::uint64_t skipped, const std::string& damage) {
    Learner learner(*service_);
    const LearnerStats& stats = learner.stats();
    EXPECT_EQ(stats.counters.env_steps, 100 * k);
    EXPECT_EQ(stats.counters.updates, 10 * k);
    EXPECT_EQ(stats.counters.learner_epoch, 2u);
    EXPECT_EQ(stats.restored_replay_steps, 16 * k);
    EXPECT_EQ(
        stats.resumed_from.filename(),
        CheckpointFiles(checkpoints(), 5).path(static_cast<std::uint64_t>(10 * k)).filename());
    EXPECT_EQ(stats.skipped_checkpoints, skipped);
    const std::string text = log();
    const std::string resumed = "resumed from " + stats.resumed_from.string();
    EXPECT_NE(text.find(resumed), std::string::npos) << text;
    EXPECT_NE(text.find("skipped " + std::to_string(skipped) + " damaged newer checkpoint"),
              std::string::npos)
        << text;
    std::printf("[figures] %s: resumed from %s (%lld env steps, %lld replay steps), skipped %llu\n",
                damage.c_str(), stats.resumed_from.filename().c_str(),
                static_cast<long long>(stats.counters.env_steps),
                static_cast<long long>(stats.restored_replay_steps),
                static_cast<unsigned long long>(stats.skipped_checkpoints));
  }

  // Checks that the log warned about `file` with `reason` and that it was set aside.
  void expect_skipped(const fs::path& file, const std::string& reason) {
    const std::string text = log();
    EXPECT_NE(text.find("warn checkpoint " + file.string() + " cannot be restored and is skipped"),
              std::string::npos)
        << text;
    EXPECT_NE(text.find(reason), std::string::npos) << text;
    EXPECT_FALSE(fs::exists(file));
    EXPECT_TRUE(fs::exists(file.string() + ".damaged")) << "kept aside for a look";
    for (const auto& path : CheckpointFiles(checkpoints(), 5).list()) EXPECT_NE(path, file);
  }

  indrive::testing::TempDir dir_{"indrive-resume"};
  std::optional<service::ServiceConfig> service_;
  std::vector<std::uint8_t> agent_bytes_;
  std::mutex log_mutex_;
  std::string log_;
};

std::vector<std::uint8_t> read(const fs::path& path) { return read_file(path); }

void write(const fs::path& path, const std::vector<std::uint8_t>& bytes) {
  std::ofstream(path, std::ios::binary | std::ios::trunc)
      .write(reinterpret_cast<const char*>(bytes.data()),
             static_cast<std::streamsize>(bytes.size()));
}

TEST_F(LearnerResumeTest, IntactCheckpointsResumeFromTheNewest) {
  write_checkpoint(1);
  write_checkpoint(2);
  write_checkpoint(3);
  expect_resumed_from(3, 0, "intact");
}

TEST_F(LearnerResumeTest, ATruncatedNewestCheckpointIsSkipped) {
  write_checkpoint(1);
  write_checkpoint(2);
  const fs::path newest = write_checkpoint(3);
  fs::resize_file(newest, fs::file_size(newest) / 2);  // a crash of the machine mid-writeback
  expect_resumed_from(2, 1, "truncated newest");
  expect_skipped(newest, "does not end with its checksum trailer");
}

TEST_F(LearnerResumeTest, ABitFlipInTheNewestCountersLineIsSkipped) {
  write_checkpoint(1);
  write_checkpoint(2);
  const fs::path newest = write_checkpoint(3);
  auto bytes = read(newest);
  const std::string text(bytes.begin(), bytes.end());
  bytes[text.find("\"env_steps\":300") + 12] ^= 0x04;  // 300 -> 700: still a number
  write(newest, bytes);
  expect_resumed_from(2, 1, "bit flip in the counters line");
  expect_skipped(newest, "is damaged: the CRC-32 of its content");
}

TEST_F(LearnerResumeTest, ABitFlipInTheNewestReplaySectionIsSkipped) {
  write_checkpoint(1);
  write_checkpoint(2);
  const fs::path newest = write_checkpoint(3);
  auto bytes = read(newest);
  const std::string text(bytes.begin(), bytes.end());
  const std::size_t line = text.find('\n') + 1;
  const auto meta = nlohmann::json::parse(text.substr(line, text.find('\n', line) - line));
  const std::size_t replay_begin =
      text.find('\n', line) + 1 + meta["agent_bytes"].get<std::size_t>();
  bytes[replay_begin + meta["replay_zstd_bytes"].get<std::size_t>() / 2] ^= 0x10;
  write(newest, bytes);
  expect_resumed_from(2, 1, "bit flip in the replay section");
  expect_skipped(newest, "is damaged: the CRC-32 of its content");
}

TEST_F(LearnerResumeTest, TwoDamagedNewerCheckpointsAreBothSkipped) {
  write_checkpoint(1);
  const fs::path second = write_checkpoint(2);
  const fs::path newest = write_checkpoint(3);
  fs::resize_file(second, 100);
  fs::resize_file(newest, 100);
  expect_resumed_from(1, 2, "two damaged");
  expect_skipped(second, "does not end with its checksum trailer");
  expect_skipped(newest, "does not end with its checksum trailer");
}

// The newest file is intact as a learner checkpoint (its checksum holds) but its agent section
// was written by another model: it fails after its replay section was read. What it held must
// not survive into the learner, which continues the older checkpoint without replay.
TEST_F(LearnerResumeTest, ACheckpointThatFailsHalfWayLeavesNothingBehind) {
  write_checkpoint(1, /*with_replay=*/false);
  agent::AgentConfig other = service_->agent();
  other.intrinsic.method = agent::Method::kRnd;
  const fs::path newest = write_checkpoint(2, true, agent::Agent(other).checkpoint_bytes());
  Learner learner(*service_);
  EXPECT_EQ(learner.stats().counters.env_steps, 100);
  EXPECT_EQ(learner.stats().restored_replay_steps, 0) << "no replay step of the skipped file";
  expect_skipped(newest, "was written by a model of other sizes or another intrinsic method");
}

TEST_F(LearnerResumeTest, WithEveryCheckpointDamagedTheLearnerRefusesToStartAndSaysWhy) {
  const fs::path first = write_checkpoint(1);
  const fs::path second = write_checkpoint(2);
  fs::resize_file(first, 10);
  auto bytes = read(second);
  bytes[bytes.size() / 2] ^= 0x01;
  write(second, bytes);
  std::string message;
  try {
    Learner learner(*service_);
    FAIL() << "a learner started although no checkpoint can be restored";
  } catch (const CheckpointError& error) {
    message = error.what();
  }
  EXPECT_NE(message.find(first.string() + ": "), std::string::npos) << message;
  EXPECT_NE(message.find(second.string() + ": "), std::string::npos) << message;
  EXPECT_NE(message.find("CRC-32"), std::string::npos) << message;
  EXPECT_NE(message.find("learner checkpoint of 10 bytes is truncated inside its first line"),
            std::string::npos)
      << message;
  EXPECT_NE(message.find("move these files out of " + checkpoints().string()), std::string::npos)
      << message;
  // Nothing renamed and nothing written: the files stay as the user left them.
  EXPECT_EQ(CheckpointFiles(checkpoints(), 5).list(), (std::vector<fs::path>{first, second}));
  EXPECT_EQ(fs::file_size(first), 10u);
  std::printf("[figures] every checkpoint damaged: %s\n", message.c_str());
}

// An evaluation and a finetune read the agent alone, from a learner checkpoint (with its
// counters) or a bare agent checkpoint (zero counters); a damaged learner checkpoint is named
// as such, not misread as a bare agent checkpoint.
TEST_F(LearnerResumeTest, AnAgentLoadsFromALearnerOrABareAgentCheckpoint) {
  const fs::path learner_file = write_checkpoint(2);
  const RestoredRun from_learner = load_agent_checkpoint(learner_file, service_->agent());
  ASSERT_NE(from_learner.agent, nullptr);
  EXPECT_EQ(from_learner.counters.updates, 20);
  EXPECT_EQ(from_learner.agent->checkpoint_bytes(), agent_bytes_);
  EXPECT_FALSE(from_learner.replay.has_value());

  const fs::path bare = dir_.path() / "agent.ckpt";
  write(bare, agent_bytes_);
  const RestoredRun from_bare = load_agent_checkpoint(bare, service_->agent());
  EXPECT_EQ(from_bare.counters.updates, 0);
  EXPECT_EQ(from_bare.agent->checkpoint_bytes(), agent_bytes_);

  fs::resize_file(learner_file, fs::file_size(learner_file) - 3);
  try {
    load_agent_checkpoint(learner_file, service_->agent());
    FAIL() << "a truncated learner checkpoint loaded";
  } catch (const CheckpointError& error) {
    EXPECT_NE(std::string(error.what()).find(learner_file.string() + ": learner checkpoint"),
              std::string::npos)
        << error.what();
  }
  EXPECT_THROW(load_agent_checkpoint(dir_.path() / "missing.bin", service_->agent()),
               CheckpointError);
}

// The newest agent that loads is taken; damaged newer files are skipped and left in place (an
// evaluation does not touch a run's rotation), and with none loading the error names each.
TEST_F(LearnerResumeTest, TheNewestAgentThatLoadsIsTakenAndDamagedOnesStayInPlace) {
  write_checkpoint(1);
  const fs::path newest = write_checkpoint(2);
  fs::resize_file(newest, fs::file_size(newest) / 2);
  const std::vector<fs::path> files = CheckpointFiles(checkpoints(), 5).list();
  const RestoredRun loaded = load_newest_agent(files, service_->agent());
  EXPECT_EQ(loaded.counters.updates, 10);
  EXPECT_EQ(loaded.skipped, 1u);
  EXPECT_TRUE(fs::exists(newest));
  EXPECT_NE(log().find("checkpoint " + newest.string() + " does not load and is skipped"),
            std::string::npos)
      << log();

  fs::resize_file(files.front(), 10);
  try {
    load_newest_agent(files, service_->agent());
    FAIL() << "an agent loaded although every checkpoint is damaged";
  } catch (const CheckpointError& error) {
    const std::string message = error.what();
    EXPECT_NE(message.find("no checkpoint loads (2 tried)"), std::string::npos) << message;
    EXPECT_NE(message.find(files.front().string() + ": "), std::string::npos) << message;
  }
}

}  // namespace
}  // namespace indrive::learner
