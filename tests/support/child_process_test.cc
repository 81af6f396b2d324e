// The tests' child processes: output to a log, the exit code, a program that cannot start, and
// children that go with a test process that dies without running its destructors.
#include "child_process.h"

#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <fstream>
#include <iterator>
#include <stdexcept>
#include <string>
#include <thread>

#include "testing.h"

namespace indrive::testing {
namespace {

using namespace std::chrono_literals;

// True once `pid` is gone or a zombie (an orphan's new parent may not reap it at once).
bool gone(pid_t pid) {
  if (::kill(pid, 0) != 0) return errno == ESRCH;
  std::ifstream stat("/proc/" + std::to_string(pid) + "/stat");
  std::string text((std::istreambuf_iterator<char>(stat)), std::istreambuf_iterator<char>());
  const auto close = text.rfind(')');
  return close != std::string::npos && close + 2 < text.size() && text[close + 2] == 'Z';
}

TEST(Child, WritesItsOutputToTheLogWithTheEnvironmentAndReturnsTheExitCode) {
  TempDir dir;
  Child child({"/bin/sh", "-c", "echo out $CHILD_TEST_VALUE; echo err >&2; exit 3"},
              dir.path() / "child.log", {{"CHILD_TEST_VALUE", "seven"}});
  EXPECT_EQ(child.wait(10s), 3);
  EXPECT_FALSE(child.running());
  EXPECT_EQ(slurp(dir.path() / "child.log"), "out seven\nerr\n");
}

TEST(Child, AProgramThatCannotStartThrows) {
  TempDir dir;
  try {
    Child child({"/no/such/program"}, dir.path() / "child.log");
    FAIL() << "a missing program started";
  } catch (const std::runtime_error& error) {
    EXPECT_NE(std::string(error.what()).find("cannot start /no/such/program"), std::string::npos)
        << error.what();
  }
}

// ctest's timeout kills a test process, which then runs no destructor: its children must not
// train on for the rest of the suite.
TEST(Child, DiesWithATestProcessKilledWithoutItsDestructors) {
  TempDir dir;
  int fds[2];
  ASSERT_EQ(::pipe(fds), 0);
  const pid_t test_process = ::fork();
  ASSERT_GE(test_process, 0);
  if (test_process == 0) {
    ::close(fds[0]);
    auto* child = new Child({"/bin/sleep", "60"}, dir.path() / "sleep.log");
    const pid_t pid = child->pid();
    [[maybe_unused]] const auto written = ::write(fds[1], &pid, sizeof pid);
    ::pause();  // until the SIGKILL below
    ::_exit(0);
  }
  ::close(fds[1]);
  pid_t child = -1;
  ASSERT_EQ(::read(fds[0], &child, sizeof child), static_cast<ssize_t>(sizeof child));
  ::close(fds[0]);
  ASSERT_GT(child, 0);
  EXPECT_FALSE(gone(child));
  ASSERT_EQ(::kill(test_process, SIGKILL), 0);
  ASSERT_EQ(::waitpid(test_process, nullptr, 0), test_process);
  const auto end = std::chrono::steady_clock::now() + 10s;
  while (!gone(child) && std::chrono::steady_clock::now() < end) std::this_thread::sleep_for(20ms);
  EXPECT_TRUE(gone(child)) << "pid " << child << " outlived the test process that started it";
  if (!gone(child)) ::kill(child, SIGKILL);
}

}  // namespace
}  // namespace indrive::testing
