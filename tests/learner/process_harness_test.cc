// The /proc readers of the process harness, against processes that end while they are read.
#include "process_harness.h"

#include <gtest/gtest.h>

#include <chrono>

#include "testing.h"

namespace indrive::testing {
namespace {

using namespace std::chrono_literals;

TEST(ChildPids, FindsAChildByItsArguments) {
  TempDir dir("indrive-harness");
  Child shell({"/bin/sh", "-c", "sleep 30 & wait"}, dir.path() / "shell.log");
  EXPECT_TRUE(wait_until(10s, [&] {
    return child_pids(shell.pid(), {"sleep", "30"}).size() == 1;
  }));
  EXPECT_TRUE(child_pids(shell.pid(), {"sleep", "31"}).empty());
  EXPECT_GE(cpu_seconds(shell.pid()), 0.0);
}

// Children that start and end all the time: reading /proc/<pid>/stat or cmdline of one that
// ended after /proc was listed fails with ESRCH. A plain std::ifstream throws then (about one
// scan in 200 did so here); the harness must see such a process as gone.
TEST(ChildPids, ChildrenEndingWhileProcIsReadAreSeenAsGone) {
  TempDir dir("indrive-harness");
  Child shell({"/bin/sh", "-c", "while :; do /bin/true; done"}, dir.path() / "shell.log");
  int scans = 0;
  const auto start = SteadyClock::now();
  while (scans < 3000 && seconds_since(start) < 10.0) {
    ASSERT_NO_THROW(child_pids(shell.pid(), {"no-such-argument"})) << "after " << scans << " scans";
    ++scans;
  }
  EXPECT_GT(scans, 100);
  EXPECT_EQ(cpu_seconds(999999999), -1.0);  // no such process
}

}  // namespace
}  // namespace indrive::testing
