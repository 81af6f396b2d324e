// Children start with their signals back (child_signals.h), whatever the parent blocks or
// ignores: without that, a child of a program that blocks SIGTERM could only be killed.
#include "indrive/basics/child_signals.h"

#include <fcntl.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>

namespace indrive {
namespace {

namespace fs = std::filesystem;

constexpr std::uint64_t bit(int signal) { return std::uint64_t{1} << (signal - 1); }

// SigBlk and SigIgn of a status file a child wrote.
std::pair<std::uint64_t, std::uint64_t> masks_in(const fs::path& status_file) {
  std::ifstream in(status_file);
  std::uint64_t blocked = ~std::uint64_t{0}, ignored = ~std::uint64_t{0};
  for (std::string line; std::getline(in, line);) {
    if (line.rfind("SigBlk:", 0) == 0) blocked = std::stoull(line.substr(7), nullptr, 16);
    if (line.rfind("SigIgn:", 0) == 0) ignored = std::stoull(line.substr(7), nullptr, 16);
  }
  return {blocked, ignored};
}

// /bin/cat of its own /proc status into `out`, spawned with `attributes` from a thread that
// blocks SIGINT and SIGTERM while the process ignores SIGPIPE.
std::pair<std::uint64_t, std::uint64_t> child_masks(const posix_spawnattr_t* attributes,
                                                    const fs::path& out) {
  std::pair<std::uint64_t, std::uint64_t> masks;
  std::thread spawner([&] {
    sigset_t stops;
    sigemptyset(&stops);
    sigaddset(&stops, SIGINT);
    sigaddset(&stops, SIGTERM);
    pthread_sigmask(SIG_BLOCK, &stops, nullptr);
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_addopen(&actions, STDOUT_FILENO, out.c_str(),
                                     O_WRONLY | O_CREAT | O_TRUNC, 0644);
    char cat[] = "/bin/cat", status[] = "/proc/self/status";
    char* argv[] = {cat, status, nullptr};
    pid_t pid = -1;
    const int failed = posix_spawn(&pid, cat, &actions, attributes, argv, environ);
    posix_spawn_file_actions_destroy(&actions);
    ASSERT_EQ(failed, 0);
    int code = 0;
    ASSERT_EQ(waitpid(pid, &code, 0), pid);
    masks = masks_in(out);
  });
  spawner.join();
  return masks;
}

class ChildSignalsTest : public ::testing::Test {
 protected:
  void SetUp() override { previous_ = ::signal(SIGPIPE, SIG_IGN); }
  void TearDown() override { ::signal(SIGPIPE, previous_); }
  fs::path out_ = fs::temp_directory_path() / ("child-signals-" + std::to_string(::getpid()));

 private:
  sighandler_t previous_ = SIG_DFL;
};

TEST_F(ChildSignalsTest, ASpawnedChildBlocksAndIgnoresNothingOfItsParents) {
  // Without the attributes the child keeps both: what the test would see without the fix.
  const auto [inherited_blocked, inherited_ignored] = child_masks(nullptr, out_);
  EXPECT_EQ(inherited_blocked & (bit(SIGINT) | bit(SIGTERM)), bit(SIGINT) | bit(SIGTERM));
  EXPECT_NE(inherited_ignored & bit(SIGPIPE), 0u);

  const ChildSignals child_signals;
  const auto [blocked, ignored] = child_masks(child_signals.attributes(), out_);
  EXPECT_EQ(blocked, 0u);
  EXPECT_EQ(ignored & (bit(SIGPIPE) | bit(SIGTERM) | bit(SIGINT)), 0u);
  fs::remove(out_);
}

TEST_F(ChildSignalsTest, AForkedChildResetsThemBeforeExec) {
  sigset_t stops, previous;
  sigemptyset(&stops);
  sigaddset(&stops, SIGTERM);
  pthread_sigmask(SIG_BLOCK, &stops, &previous);
  const pid_t pid = ::fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    reset_signals_for_exec();
    const int fd = ::open(out_.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    ::dup2(fd, STDOUT_FILENO);
    ::execl("/bin/cat", "cat", "/proc/self/status", static_cast<char*>(nullptr));
    ::_exit(127);
  }
  int code = 0;
  ASSERT_EQ(waitpid(pid, &code, 0), pid);
  pthread_sigmask(SIG_SETMASK, &previous, nullptr);
  ASSERT_TRUE(WIFEXITED(code) && WEXITSTATUS(code) == 0);
  const auto [blocked, ignored] = masks_in(out_);
  EXPECT_EQ(blocked, 0u);
  EXPECT_EQ(ignored & bit(SIGPIPE), 0u);
  fs::remove(out_);
}

}  // namespace
}  // namespace indrive
