// Two real processes on this host exchange a 10 MB PolicySnapshot and 1,000 TrajectoryChunks
// of 64 frames of 128x128 class ids, over each shipped XML profile. The receiver starts after
// the snapshot was written (TRANSIENT_LOCAL late join), verifies every message against the
// synthetic generator, and counts four malformed chunks as drops. SecureUdpProfile runs the
// UDP transfer again with DDS Security on, so the two runs' figures show what security costs.
#include <gtest/gtest.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <string>
#include <thread>
#include <vector>

#include "indrive/basics/log.h"
#include "testing.h"

extern char** environ;

namespace indrive::testing {
namespace {

constexpr int kChunks = 1000;

// A child process that is killed if still running when this object dies.
class Child {
 public:
  explicit Child(std::vector<std::string> args) {
    std::vector<char*> argv;
    for (auto& arg : args) argv.push_back(arg.data());
    argv.push_back(nullptr);
    if (posix_spawn(&pid_, argv[0], nullptr, nullptr, argv.data(), environ) != 0) pid_ = -1;
  }
  ~Child() {
    if (pid_ > 0 && !exited_) {
      ::kill(pid_, SIGKILL);
      ::waitpid(pid_, nullptr, 0);
    }
  }
  bool started() const { return pid_ > 0; }
  // Waits up to `timeout` for the exit; returns the exit code, or -1 on timeout or signal.
  int wait(std::chrono::seconds timeout) {
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    while (std::chrono::steady_clock::now() < deadline) {
      int status = 0;
      if (::waitpid(pid_, &status, WNOHANG) == pid_) {
        exited_ = true;
        return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    return -1;
  }

 private:
  pid_t pid_ = -1;
  bool exited_ = false;
};

std::map<std::string, double> read_figures(const std::filesystem::path& path) {
  std::map<std::string, double> figures;
  std::ifstream in(path);
  std::string name;
  double value = 0.0;
  while (in >> name >> value) figures[name] = value;
  return figures;
}

bool wait_for_file(const std::filesystem::path& path, std::chrono::seconds timeout) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (!std::filesystem::exists(path)) {
    if (std::chrono::steady_clock::now() >= deadline) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  return true;
}

// DDS Security of one side of the transfer: a folder of deploy/dds/make_security.sh and a role.
struct PeerSecurity {
  std::string dir, role;
  std::vector<std::string> args() const {
    if (dir.empty()) return {};
    return {"--security", dir, "--role", role};
  }
};

// `args` followed by the flags of `security`.
std::vector<std::string> with_security(std::vector<std::string> args,
                                       const PeerSecurity& security) {
  for (auto& arg : security.args()) args.push_back(arg);
  return args;
}

// Runs publisher and late-joining receiver over the profiles file `profiles`; `profile` names
// it in the log.
void run_transfer(const std::string& profile, const std::string& profiles, const TempDir& dir,
                  const PeerSecurity& publisher_security = {},
                  const PeerSecurity& receiver_security = {}) {
  const std::string domain = std::to_string(unique_domain_id());
  const std::string run_id = "transfer-" + std::to_string(::getpid());
  const std::string peer = INDRIVE_DDS_PEER;
  const auto ready = dir.path() / "ready";
  const auto publisher_result = dir.path() / "publisher.txt";
  const auto receiver_result = dir.path() / "receiver.txt";

  Child publisher(
      with_security({peer, "publish", "--profiles", profiles, "--domain", domain, "--run-id",
                     run_id, "--chunks", std::to_string(kChunks), "--snapshot-mb", "10", "--ready",
                     ready.string(), "--result", publisher_result.string(), "--timeout", "40"},
                    publisher_security));
  ASSERT_TRUE(publisher.started()) << "could not start " << peer;
  ASSERT_TRUE(wait_for_file(ready, std::chrono::seconds(20)))
      << "publisher never wrote the snapshot";

  // The receiver joins only now, after the snapshot was written.
  Child receiver(
      with_security({peer, "receive", "--profiles", profiles, "--domain", domain, "--run-id",
                     run_id, "--chunks", std::to_string(kChunks), "--snapshot-mb", "10", "--result",
                     receiver_result.string(), "--timeout", "40"},
                    receiver_security));
  ASSERT_TRUE(receiver.started());
  const int receiver_code = receiver.wait(std::chrono::seconds(50));
  const int publisher_code = publisher.wait(std::chrono::seconds(10));

  const auto received = read_figures(receiver_result);
  const auto sent = read_figures(publisher_result);
  EXPECT_EQ(receiver_code, 0);
  EXPECT_EQ(publisher_code, 0);
  EXPECT_EQ(received.at("snapshot_ok"), 1) << "late joiner did not get the snapshot intact";
  EXPECT_EQ(received.at("snapshot_bad"), 0);
  EXPECT_EQ(received.at("chunks_ok"), kChunks);
  EXPECT_EQ(received.at("duplicates"), 0);
  EXPECT_EQ(received.at("mismatches"), 0);
  EXPECT_EQ(received.at("bad_checksum"), 1);
  EXPECT_EQ(received.at("wrong_schema"), 1);
  EXPECT_EQ(received.at("wrong_run"), 1);
  EXPECT_EQ(received.at("bad_shape"), 1);
  ASSERT_EQ(sent.at("acked"), 1);

  INDRIVE_LOG(kInfo, "test") << profile << ": late joiner created its participant in "
                             << received.at("participant_s") << " s and had the 10 MB snapshot "
                             << received.at("snapshot_s") << " s after start; " << kChunks
                             << " chunks (" << sent.at("wire_mb") << " MB compressed, "
                             << sent.at("raw_mb") << " MB of frames, ratio "
                             << sent.at("compression_ratio") << ") sent and acknowledged in "
                             << sent.at("send_s") << " s = " << sent.at("wire_mb_per_s")
                             << " MB/s on the wire, " << sent.at("raw_mb_per_s")
                             << " MB/s of frames; write retries " << sent.at("write_retries");
  INDRIVE_LOG(kInfo, "test") << profile << ": receiver saw chunks for " << received.at("chunk_s")
                             << " s (" << sent.at("wire_mb") / received.at("chunk_s")
                             << " MB/s on the wire from first to last chunk); generating them "
                             << "took the publisher " << sent.at("generate_s") << " s";
  ::testing::Test::RecordProperty("wire_mb_per_s", std::to_string(sent.at("wire_mb_per_s")));
}

void run_transfer(const std::string& profile) {
  TempDir dir("indrive-dds-transfer");
  run_transfer(profile, source_path("deploy/dds/" + profile).string(), dir);
}

TEST(DdsTransfer, DefaultUdpProfile) { run_transfer("default.xml"); }

TEST(DdsTransfer, SingleHostSharedMemoryProfile) { run_transfer("single_host.xml"); }

// The UDP transfer with DDS Security on: authentication, access control, and encryption of
// discovery, RTPS messages and payloads as the governance of make_security.sh asks. The
// receiver is the shipped observer role; the publisher writes both the snapshot and the chunks,
// which no shipped role may do, so it runs as a learner whose permissions this test widens by
// the trajectory topic and signs again with the folder's CA (the shipped roles stay as they are).
TEST(DdsTransfer, SecureUdpProfile) {
  TempDir dir("indrive-dds-transfer");
  const auto security = dir.path() / "security";
  make_security_folder(security);
  allow_publishing(security, "learner", "indrive/trajectory");

  run_transfer("default.xml + DDS Security", source_path("deploy/dds/default.xml").string(), dir,
               {.dir = security.string(), .role = "learner"},
               {.dir = security.string(), .role = "observer"});
}

// Discovery through a server (no multicast): the shipped file with the server's port moved to
// one of this test's own, so parallel runs do not share a server.
TEST(DdsTransfer, DiscoveryServerProfile) {
  TempDir dir("indrive-dds-transfer");
  const std::string port = std::to_string(20000 + (::getpid() * 13 + unique_domain_id()) % 20000);
  std::ifstream in(source_path("deploy/dds/discovery_server.xml"));
  std::string xml((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const std::string shipped_port = "<port>11811</port>";
  const auto at = xml.find(shipped_port);
  ASSERT_NE(at, std::string::npos) << "discovery_server.xml no longer names port 11811";
  xml.replace(at, shipped_port.size(), "<port>" + port + "</port>");
  const auto profiles = dir.path() / "discovery_server.xml";
  std::ofstream(profiles) << xml;

  Child server({INDRIVE_DISCOVERY_SERVER, "-i", "0", "-l", "127.0.0.1", "-p", port});
  ASSERT_TRUE(server.started());
  run_transfer("discovery_server.xml", profiles.string(), dir);
}

}  // namespace
}  // namespace indrive::testing
