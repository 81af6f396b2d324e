#include "indrive/dds/participant.h"

#include <gtest/gtest.h>

#include <atomic>
#include <cstdlib>
#include <fstream>
#include <set>

#include "indrive/basics/config.h"
#include "indrive/dds/security.h"
#include "testing.h"

namespace indrive::dds {
namespace {

using namespace std::chrono_literals;

// Every test here loads the same profiles file: Fast DDS keeps loaded profiles per process,
// and two files that define the same profile names cannot both be loaded in one process.
std::string profiles() { return testing::source_path("deploy/dds/default.xml").string(); }

template <typename F>
std::string error_of(F&& make) {
  return testing::error_of<DdsError>(std::forward<F>(make));
}

TEST(DdsParticipant, MissingProfilesFileNamesThePath) {
  const auto message =
      error_of([] { Participant participant({.profiles_file = "/nonexistent/profiles.xml"}); });
  EXPECT_NE(message.find("/nonexistent/profiles.xml"), std::string::npos) << message;
  EXPECT_NE(message.find("does not exist"), std::string::npos) << message;
}

TEST(DdsParticipant, ProfilesFileComesFromEnvironmentWhenNoFlag) {
  ::unsetenv(kProfilesEnvVar);
  const auto message = error_of([] { resolve_profiles_file(""); });
  EXPECT_NE(message.find("FASTRTPS_DEFAULT_PROFILES_FILE"), std::string::npos) << message;
  ::setenv(kProfilesEnvVar, profiles().c_str(), 1);
  EXPECT_EQ(resolve_profiles_file("").string(), profiles());
  const std::string other = testing::source_path("deploy/dds/single_host.xml").string();
  EXPECT_EQ(resolve_profiles_file(other).string(), other) << "an explicit path wins";
  ::unsetenv(kProfilesEnvVar);
}

TEST(DdsParticipant, MalformedXmlIsReported) {
  testing::TempDir dir;
  const auto path = dir.path() / "broken.xml";
  std::ofstream(path) << "<dds><profiles><participant profile_name=\"x\">";
  const auto message = error_of([&] { Participant participant({.profiles_file = path.string()}); });
  EXPECT_NE(message.find("could not be loaded"), std::string::npos) << message;
}

TEST(DdsParticipant, UnknownProfilesAreNamed) {
  const auto participant_message = error_of([] {
    Participant participant({.profiles_file = profiles(), .participant_profile = "no_such"});
  });
  EXPECT_NE(participant_message.find("no <participant> profile named 'no_such'"), std::string::npos)
      << participant_message;

  Participant participant({.domain_id = testing::unique_domain_id(), .profiles_file = profiles()});
  const auto writer_message = error_of(
      [&] { participant.make_writer<msg::StepAllowance>("indrive/allowance", "no_writer"); });
  EXPECT_NE(writer_message.find("no <data_writer> profile named 'no_writer'"), std::string::npos)
      << writer_message;
  const auto domain_message =
      error_of([] { Participant participant({.domain_id = 300, .profiles_file = profiles()}); });
  EXPECT_NE(domain_message.find("0..232"), std::string::npos) << domain_message;
}

TEST(DdsParticipant, SecondProfilesFileInOneProcessIsRefused) {
  Participant first({.domain_id = testing::unique_domain_id(), .profiles_file = profiles()});
  const auto message = error_of([] {
    Participant second({.profiles_file = testing::source_path("deploy/dds/single_host.xml")});
  });
  EXPECT_NE(message.find("already uses DDS profiles from"), std::string::npos) << message;

  // Fast DDS loads the environment's file by itself: a different explicit file is refused too.
  ::setenv(kProfilesEnvVar, testing::source_path("deploy/dds/single_host.xml").c_str(), 1);
  const auto env_message = error_of([] { Participant third({.profiles_file = profiles()}); });
  ::unsetenv(kProfilesEnvVar);
  EXPECT_NE(env_message.find("FASTRTPS_DEFAULT_PROFILES_FILE names"), std::string::npos)
      << env_message;
}

TEST(DdsParticipantDeathTest, OutlivingWriterIsABug) {
  // Fast DDS runs threads: re-execute the test binary instead of forking this process.
  GTEST_FLAG_SET(death_test_style, "threadsafe");
  EXPECT_DEATH(
      {
        auto participant = std::make_unique<Participant>(ParticipantOptions{
            .domain_id = testing::unique_domain_id(), .profiles_file = profiles()});
        auto writer = participant->make_writer<msg::Heartbeat>();
        participant.reset();
      },
      "destroy writers and readers before their participant");
}

TEST(DdsParticipant, LateReaderGetsTransientLocalAllowance) {
  const int domain = testing::unique_domain_id();
  Participant learner({.domain_id = domain, .profiles_file = profiles()});
  Participant actor({.domain_id = domain, .profiles_file = profiles()});
  auto writer = learner.make_writer<msg::StepAllowance>();
  msg::StepAllowance allowance;
  allowance.run_id("run");
  allowance.total_env_steps(4096);
  allowance.replay_ratio(32.0);
  seal(allowance);
  ASSERT_TRUE(writer->write(allowance));
  allowance.total_env_steps(8192);  // KEEP_LAST 1: only this one must reach a late reader
  ASSERT_TRUE(writer->write(allowance));

  std::atomic<std::uint64_t> received{0};
  std::atomic<int> samples{0};
  auto reader = actor.make_reader<msg::StepAllowance>([&](const msg::StepAllowance& sample) {
    if (validate(sample, "run") == DropReason::kOk) received = sample.total_env_steps();
    samples.fetch_add(1);
  });
  ASSERT_TRUE(reader->wait_for_matched(1, 10s));
  for (int i = 0; i < 500 && received.load() == 0; ++i) std::this_thread::sleep_for(10ms);
  EXPECT_EQ(received.load(), 8192u);
  EXPECT_EQ(samples.load(), 1);
}

// dds.snapshot_rate_mb_s replaces the policy writer's throughput limit (and only its); a
// negative rate is refused with the key's name.
TEST(DdsParticipant, SnapshotRateReplacesThePolicyWritersLimitOnly) {
  const int domain = testing::unique_domain_id();
  Participant shipped({.domain_id = domain, .profiles_file = profiles()});
  auto shipped_policy = shipped.make_writer<msg::PolicySnapshot>();
  EXPECT_EQ(shipped_policy->native()->get_qos().throughput_controller().bytesPerPeriod, 1048576u)
      << "the shipped profile's 100 MB/s";

  Participant slow({.domain_id = domain, .profiles_file = profiles(), .snapshot_rate_mb_s = 1.6});
  auto policy = slow.make_writer<msg::PolicySnapshot>();
  const auto& limit = policy->native()->get_qos().throughput_controller();
  EXPECT_EQ(limit.bytesPerPeriod, 16000u) << "1.6 MB/s as bytes per 10 ms";
  EXPECT_EQ(limit.periodMillisecs, 10u);
  auto chunks = slow.make_writer<msg::TrajectoryChunk>();
  EXPECT_NE(chunks->native()->get_qos().throughput_controller().bytesPerPeriod, 16000u);

  EXPECT_NE(
      error_of([&] {
        Participant({.domain_id = domain, .profiles_file = profiles(), .snapshot_rate_mb_s = -1.0});
      }).find("dds.snapshot_rate_mb_s"),
      std::string::npos);
}

TEST(DdsParticipant, ThrowingCallbackIsCountedNotPropagated) {
  const int domain = testing::unique_domain_id();
  Participant participant({.domain_id = domain, .profiles_file = profiles()});
  auto writer = participant.make_writer<msg::EpisodeResult>();
  auto reader = participant.make_reader<msg::EpisodeResult>(
      [](const msg::EpisodeResult&) { throw std::runtime_error("consumer bug"); });
  ASSERT_TRUE(writer->wait_for_matched(1, 10s));
  msg::EpisodeResult result;
  seal(result);
  for (int i = 0; i < 3; ++i) ASSERT_TRUE(writer->write(result));
  for (int i = 0; i < 500 && reader->callback_failures() < 3; ++i)
    std::this_thread::sleep_for(10ms);
  EXPECT_EQ(reader->callback_failures(), 3u);
}

TEST(DdsParticipant, HeartbeatsKeepOneSamplePerKey) {
  const int domain = testing::unique_domain_id();
  Participant participant({.domain_id = domain, .profiles_file = profiles()});
  auto writer = participant.make_writer<msg::Heartbeat>();
  std::mutex mutex;
  std::map<std::pair<int, std::uint32_t>, std::uint64_t> latest;
  auto reader = participant.make_reader<msg::Heartbeat>([&](const msg::Heartbeat& beat) {
    std::lock_guard<std::mutex> lock(mutex);
    latest[{beat.role(), beat.id()}] = beat.env_steps();
  });
  ASSERT_TRUE(writer->wait_for_matched(1, 10s));
  msg::Heartbeat beat;
  beat.role(msg::ROLE_ACTOR);
  beat.id(2);
  beat.env_steps(10);
  seal(beat);
  ASSERT_TRUE(writer->write(beat));
  for (int i = 0; i < 500; ++i) {
    {
      std::lock_guard<std::mutex> lock(mutex);
      if (!latest.empty()) break;
    }
    std::this_thread::sleep_for(10ms);
  }
  std::lock_guard<std::mutex> lock(mutex);
  ASSERT_EQ(latest.size(), 1u);
  EXPECT_EQ((latest[{msg::ROLE_ACTOR, 2u}]), 10u);
}

// A process's shared-memory participants take a new id each (a recreated one must not take the
// dead one's port), other processes start at ids that look random, all in range.
TEST(DdsParticipant, SharedMemoryIdsMoveWithThePidAndTheCount) {
  for (const long pid : {1L, 4242L, 99999L}) {
    std::set<int> of_process;
    for (int count = 0; count < kSharedMemoryParticipantIds; ++count) {
      const int id = shared_memory_participant_id(pid, count);
      EXPECT_GE(id, 0);
      EXPECT_LT(id, kSharedMemoryParticipantIds);
      of_process.insert(id);
    }
    EXPECT_EQ(of_process.size(), static_cast<std::size_t>(kSharedMemoryParticipantIds))
        << "no id again before every other was used";
  }
  // Processes started one after another have consecutive pids: the replacement participants of
  // one (counts 1-3) take the first id of the next about as often as chance would (1 in 50
  // each), not always (as with pid + count, where (p, 1) and (p + 1, 0) always met).
  int met = 0, pairs = 0;
  for (long pid = 1000; pid < 3000; ++pid) {
    for (int count = 1; count <= 3; ++count, ++pairs) {
      met += shared_memory_participant_id(pid, count) == shared_memory_participant_id(pid + 1, 0);
    }
  }
  EXPECT_LT(met, pairs / 25) << met << " of " << pairs;
  // A restarted process (another pid) rarely starts on the id of the one it replaces.
  int same_start = 0;
  for (long pid = 1000; pid < 3000; ++pid) {
    for (const long next : {pid + 1, pid + 7, pid + 31}) {
      same_start += shared_memory_participant_id(next, 0) == shared_memory_participant_id(pid, 0);
    }
  }
  EXPECT_LT(same_start, 6000 / 25) << same_start;
  // Ports of domain 232 (the highest): 7400 + 250 x 232 + 11 + 2 x id <= 65535.
  EXPECT_LE(7400 + 250 * 232 + 11 + 2 * (kSharedMemoryParticipantIds - 1), 65535);
  GTEST_FLAG_SET(death_test_style, "threadsafe");
  EXPECT_DEATH(shared_memory_participant_id(-1, 0), "pid");
}

// The UDP profiles keep Fast DDS's own choice (their ports are what firewall rules name).
TEST(DdsParticipant, UdpParticipantsLetFastDdsChooseTheId) {
  Participant participant({.domain_id = testing::unique_domain_id(), .profiles_file = profiles()});
  EXPECT_FALSE(participant.uses_shared_memory());
  EXPECT_EQ(participant.participant_id(), -1);
  EXPECT_EQ(participant.native()->get_qos().wire_protocol().participant_id, -1);
}

TEST(DdsDiscoveryServer, AddressesParseWithTheDefaultPortAndResolve) {
  const ServerAddress numeric = parse_discovery_server("10.1.2.3:12000", "--discovery-server");
  EXPECT_EQ(numeric.host, "10.1.2.3");
  EXPECT_EQ(numeric.ipv4, "10.1.2.3");
  EXPECT_EQ(numeric.port, 12000);
  const ServerAddress named = parse_discovery_server("localhost", "--discovery-server");
  EXPECT_EQ(named.ipv4, "127.0.0.1");
  EXPECT_EQ(named.port, kDefaultDiscoveryPort);
  EXPECT_EQ(named.describe(), "localhost:11811 (127.0.0.1) from --discovery-server");
}

TEST(DdsDiscoveryServer, BadAddressesSayWhatIsWrongAndWhereTheyCameFrom) {
  const auto message = [](const std::string& text) {
    return error_of([&] { parse_discovery_server(text, "$INDRIVE_DISCOVERY_SERVER"); });
  };
  for (const std::string text : {"10.0.0.1:", "10.0.0.1:0", "10.0.0.1:70000", "host:port"}) {
    const std::string error = message(text);
    EXPECT_NE(error.find("$INDRIVE_DISCOVERY_SERVER is '" + text + "'"), std::string::npos)
        << error;
    EXPECT_NE(error.find("port after ':' must be 1..65535"), std::string::npos) << error;
  }
  EXPECT_NE(message(":11811").find("give the server as HOST:PORT"), std::string::npos);
  const std::string unresolved = message("no-such-host.invalid:11811");
  EXPECT_NE(unresolved.find("cannot resolve 'no-such-host.invalid'"), std::string::npos)
      << unresolved;
}

TEST(DdsDiscoveryServer, TheFlagWinsOverTheEnvironmentWhichWinsOverNothing) {
  ::unsetenv(kDiscoveryServerEnvVar);
  EXPECT_FALSE(resolve_discovery_server("").has_value());
  ::setenv(kDiscoveryServerEnvVar, "127.0.0.1:15000", 1);
  const auto from_env = resolve_discovery_server("");
  ASSERT_TRUE(from_env.has_value());
  EXPECT_EQ(from_env->port, 15000);
  EXPECT_EQ(from_env->source, "$INDRIVE_DISCOVERY_SERVER");
  const auto from_flag = resolve_discovery_server("127.0.0.1:16000");
  ASSERT_TRUE(from_flag.has_value());
  EXPECT_EQ(from_flag->port, 16000);
  ::unsetenv(kDiscoveryServerEnvVar);
}

// default.xml discovers by multicast: a server address there would be silently ignored by
// Fast DDS, so it is refused with the profile to use instead.
TEST(DdsDiscoveryServer, AServerWithAMulticastProfileIsRefused) {
  const auto message = error_of([] {
    Participant participant({.domain_id = testing::unique_domain_id(),
                             .profiles_file = profiles(),
                             .discovery_server = "127.0.0.1:11811"});
  });
  EXPECT_NE(message.find("does not make discovery-server clients"), std::string::npos) << message;
  EXPECT_NE(message.find("deploy/dds/discovery_server.xml"), std::string::npos) << message;
}

TEST(DdsConfig, KeysFeedTheParticipantOptions) {
  config::Schema schema;
  declare_config(schema);
  const auto options = participant_options(config::Config::resolve(
      schema, {.overrides = {"dds.domain_id=9", "dds.profiles_file=x.xml"}}));
  EXPECT_EQ(options.domain_id, 9);
  EXPECT_EQ(options.profiles_file, "x.xml");
  EXPECT_EQ(options.participant_profile, "indrive_participant");
  EXPECT_EQ(options.security_dir, "") << "DDS Security is off unless a folder is named";
  EXPECT_EQ(options.security_role, "");

  // The security keys: a folder, and a role that must be one of the four or empty (the
  // program's own role then).
  const auto secure = config::Config::resolve(
      schema, {.overrides = {"dds.security_dir=runs/r1/security", "dds.security_role=observer"}});
  EXPECT_EQ(participant_options(secure).security_dir, "runs/r1/security");
  EXPECT_EQ(participant_options(secure).security_role, "observer");
  EXPECT_EQ(security_role(secure, "learner"), "observer");
  EXPECT_EQ(security_role(config::Config::resolve(schema, {}), "learner"), "learner");
  EXPECT_THROW(config::Config::resolve(schema, {.overrides = {"dds.security_role=pilot"}}),
               config::ConfigError);
}

}  // namespace
}  // namespace indrive::dds
