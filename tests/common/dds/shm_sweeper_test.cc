#include "indrive/dds/shm_sweeper.h"

#include <fcntl.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/file.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <regex>
#include <set>
#include <string>
#include <thread>

#include "child_process.h"
#include "testing.h"

namespace indrive::dds {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;
using Clock = SharedMemorySweeper::Clock;

// Writes `bytes` bytes to `path`, dated `age` ago.
void make_file(const fs::path& path, std::size_t bytes, std::chrono::seconds age = 1h) {
  std::ofstream(path, std::ios::binary) << std::string(bytes, 'x');
  fs::last_write_time(path, fs::file_time_type::clock::now() - age);
}

// A segment and its lock file, as Fast DDS names them.
void make_segment(const fs::path& dir, const std::string& hex, std::size_t bytes,
                  std::chrono::seconds age = 1h) {
  make_file(dir / ("fastrtps_" + hex), bytes);
  make_file(dir / ("fastrtps_" + hex + "_el"), 0, age);
}

// Holds the flock of a file like the owner of a live segment does.
class HeldLock {
 public:
  explicit HeldLock(const fs::path& path) : fd_(::open(path.c_str(), O_RDONLY)) {
    EXPECT_GE(fd_, 0);
    EXPECT_EQ(::flock(fd_, LOCK_EX | LOCK_NB), 0);
  }
  ~HeldLock() { release(); }
  void release() {
    if (fd_ >= 0) ::close(fd_);
    fd_ = -1;
  }

 private:
  int fd_;
};

TEST(SharedMemorySweeper, KnowsFastDdsSegmentLockNames) {
  EXPECT_TRUE(is_segment_lock_name("fastrtps_0149472a6fae27c0_el"));
  EXPECT_FALSE(is_segment_lock_name("fastrtps_0149472a6fae27c0"));     // the segment itself
  EXPECT_FALSE(is_segment_lock_name("fastrtps_0149472a6fae27c_el"));   // 15 digits
  EXPECT_FALSE(is_segment_lock_name("fastrtps_0149472A6FAE27C0_el"));  // not lowercase
  EXPECT_FALSE(is_segment_lock_name("fastrtps_port7411_el"));          // a port
  EXPECT_FALSE(is_segment_lock_name("sem.fastrtps_port7411_mutex"));
  EXPECT_FALSE(is_segment_lock_name("other_0149472a6fae27c0_el"));
}

TEST(SharedMemorySweeper, RemovesOnlySegmentsFoundFreeInTwoSweepsAGraceApart) {
  testing::TempDir dir("indrive-shm-sweep");
  make_segment(dir.path(), "00000000000000d1", 4096);              // dead owner
  make_segment(dir.path(), "00000000000000a1", 2048);              // live owner
  make_segment(dir.path(), "00000000000000f1", 1024, /*age=*/0s);  // just made
  make_segment(dir.path(), "00000000000000b1", 512);  // owner alive at first, then dead
  make_file(dir.path() / "fastrtps_port7411", 100);
  make_file(dir.path() / "fastrtps_port7411_el", 0);
  make_file(dir.path() / "unrelated", 10);
  HeldLock live(dir.path() / "fastrtps_00000000000000a1_el");
  auto later_held = std::make_unique<HeldLock>(dir.path() / "fastrtps_00000000000000b1_el");

  const std::uintmax_t d1_bytes = allocated_bytes(dir.path() / "fastrtps_00000000000000d1");
  const std::uintmax_t b1_bytes = allocated_bytes(dir.path() / "fastrtps_00000000000000b1");
  EXPECT_GE(d1_bytes, 4096u);
  SharedMemorySweeper sweeper(dir.path(), 60s);
  const auto t0 = Clock::now();
  auto swept = sweeper.sweep(t0);
  EXPECT_EQ(swept.live, 3);  // a1, b1, and f1 (too young to judge)
  EXPECT_EQ(swept.waiting, 1);
  EXPECT_EQ(swept.removed, 0);

  later_held->release();  // b1's owner dies
  swept = sweeper.sweep(t0 + 30s);
  EXPECT_EQ(swept.live, 2);
  EXPECT_EQ(swept.waiting, 2);  // d1 within its grace, b1 seen free for the first time
  EXPECT_EQ(swept.removed, 0);
  EXPECT_TRUE(fs::exists(dir.path() / "fastrtps_00000000000000d1"));

  swept = sweeper.sweep(t0 + 61s);
  EXPECT_EQ(swept.removed, 1);
  EXPECT_EQ(swept.removed_bytes, d1_bytes);
  EXPECT_FALSE(fs::exists(dir.path() / "fastrtps_00000000000000d1"));
  EXPECT_FALSE(fs::exists(dir.path() / "fastrtps_00000000000000d1_el"));
  EXPECT_TRUE(fs::exists(dir.path() / "fastrtps_00000000000000b1"));

  swept = sweeper.sweep(t0 + 91s);
  EXPECT_EQ(swept.removed, 1);  // b1, 60 s after it was first seen free
  EXPECT_EQ(swept.removed_bytes, b1_bytes);
  EXPECT_FALSE(fs::exists(dir.path() / "fastrtps_00000000000000b1"));

  // Never touched: the live segment, the young one, the port and other files.
  swept = sweeper.sweep(t0 + 1h);
  EXPECT_EQ(swept.removed, 0);
  for (const char* name :
       {"fastrtps_00000000000000a1", "fastrtps_00000000000000a1_el", "fastrtps_00000000000000f1",
        "fastrtps_00000000000000f1_el", "fastrtps_port7411", "fastrtps_port7411_el", "unrelated"}) {
    EXPECT_TRUE(fs::exists(dir.path() / name)) << name;
  }
}

TEST(SharedMemorySweeper, ALockTakenAgainRestartsTheGrace) {
  testing::TempDir dir("indrive-shm-sweep");
  make_segment(dir.path(), "00000000000000c1", 64);
  const fs::path lock = dir.path() / "fastrtps_00000000000000c1_el";
  SharedMemorySweeper sweeper(dir.path(), 60s);
  const auto t0 = Clock::now();
  EXPECT_EQ(sweeper.sweep(t0).waiting, 1);
  {
    HeldLock held(lock);
    EXPECT_TRUE(lock_is_held(lock));
    EXPECT_EQ(sweeper.sweep(t0 + 30s).live, 1);
  }
  EXPECT_FALSE(lock_is_held(lock));
  EXPECT_EQ(sweeper.sweep(t0 + 70s).removed, 0);  // free again since 70 s only
  EXPECT_EQ(sweeper.sweep(t0 + 131s).removed, 1);
  EXPECT_TRUE(lock_is_held(dir.path() / "missing_el")) << "a missing file counts as held";
}

// The segments Fast DDS maps in process `pid`, by file name.
std::set<std::string> mapped_segments(pid_t pid) {
  std::set<std::string> names;
  std::ifstream maps("/proc/" + std::to_string(pid) + "/maps");
  const std::regex segment(R"(/dev/shm/(fastrtps_[0-9a-f]{16})$)");
  std::smatch match;
  for (std::string line; std::getline(maps, line);) {
    if (std::regex_search(line, match, segment)) names.insert(match[1]);
  }
  return names;
}

// Against Fast DDS itself: the segment of a shared-memory participant is locked while its
// process lives, free after a kill -9, and the sweeper removes it. The sweeper works on hard
// links of the segment's files in a folder of the test's own on the same file system (a link
// shares the inode and so the flock), so that it never touches other processes' segments.
TEST(SharedMemorySweeper, RemovesTheSegmentOfAParticipantKilledWithSigkill) {
  if (!fs::is_directory("/dev/shm")) GTEST_SKIP() << "no /dev/shm here";
  testing::TempDir log_dir("indrive-shm-sweep-log");
  const fs::path links = fs::path("/dev/shm") / ("indrive-shm-sweep-" + std::to_string(::getpid()));
  fs::create_directories(links);
  struct RemoveLinks {
    fs::path path;
    ~RemoveLinks() {
      std::error_code ignored;
      fs::remove_all(path, ignored);
    }
  } remove_links{links};

  testing::Child peer(
      {INDRIVE_DDS_PEER, "receive", "--profiles",
       testing::source_path("deploy/dds/single_host.xml").string(), "--domain",
       std::to_string(testing::unique_domain_id()), "--run-id", "sweep", "--chunks", "1",
       "--result", (log_dir.path() / "result.txt").string(), "--timeout", "60"},
      log_dir.path() / "peer.log");
  std::set<std::string> segments;
  for (int i = 0; i < 300 && segments.empty(); ++i) {
    std::this_thread::sleep_for(100ms);
    segments = mapped_segments(peer.pid());
  }
  ASSERT_EQ(segments.size(), 1u) << "the peer's own segment, alone in its domain\n"
                                 << testing::slurp(log_dir.path() / "peer.log");
  const std::string name = *segments.begin();
  const fs::path segment = fs::path("/dev/shm") / name;
  const fs::path lock = fs::path("/dev/shm") / (name + "_el");
  ASSERT_TRUE(fs::exists(lock)) << "Fast DDS 2.9 names a segment's lock file " << lock;
  EXPECT_TRUE(is_segment_lock_name(lock.filename().string()));
  EXPECT_TRUE(lock_is_held(lock)) << "a live participant holds its segment's lock";
  fs::create_hard_link(segment, links / name);
  fs::create_hard_link(lock, links / (name + "_el"));
  // Old enough to be judged (the rule leaves lock files younger than 10 s alone).
  fs::last_write_time(lock, fs::file_time_type::clock::now() - 1h);

  SharedMemorySweeper sweeper(links, 0s);
  const auto t0 = Clock::now();
  EXPECT_EQ(sweeper.sweep(t0).live, 1);

  peer.signal(SIGKILL);
  EXPECT_EQ(peer.wait(10s), 128 + SIGKILL);
  EXPECT_TRUE(fs::exists(segment)) << "a kill -9 leaves the segment behind";
  EXPECT_FALSE(lock_is_held(lock));
  const std::uintmax_t bytes = allocated_bytes(segment);
  EXPECT_EQ(sweeper.sweep(t0 + 1s).waiting, 1);
  const auto swept = sweeper.sweep(t0 + 2s);
  EXPECT_EQ(swept.removed, 1);
  EXPECT_EQ(swept.removed_bytes, bytes);
  EXPECT_FALSE(fs::exists(links / name));
  std::printf("[figures] a kill -9 left a segment of %.1f MiB in memory (%.0f MiB mapped; %s)\n",
              static_cast<double>(bytes) / (1 << 20),
              static_cast<double>(fs::file_size(segment)) / (1 << 20), name.c_str());
  // The originals are the test's to clean up (the launcher's sweeper would, a minute later).
  fs::remove(segment);
  fs::remove(lock);
}

}  // namespace
}  // namespace indrive::dds
