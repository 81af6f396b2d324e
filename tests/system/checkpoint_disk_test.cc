// Checkpoints on a full disk: a size-limited tmpfs, mounted in a child process's own mount
// namespace (so nothing outside it sees the mount and it vanishes with the child). A write that
// does not fit throws IoError, leaves no temporary file and leaves the previous checkpoint
// byte for byte; a learner whose checkpoints folder is full keeps training, counts the failures
// in metrics.jsonl, and exits non-zero when its final checkpoint cannot be written.
//
// Mounting needs root (CI runs as root) and a kernel and container that allow a new mount
// namespace; elsewhere the tests skip and say why.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <sched.h>
#include <signal.h>
#include <sys/mount.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <fstream>
#include <functional>
#include <random>

#include "indrive/agent/agent.h"
#include "indrive/basics/run_dir.h"
#include "indrive/learner/learner.h"
#include "process_harness.h"
#include "testing.h"

namespace indrive::learner {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;

constexpr int kNoMount = 42;  // the child could not make its tmpfs: the test skips
constexpr const char* kNoTmpfs =
    "no size-limited tmpfs can be mounted here (a container needs CAP_SYS_ADMIN and a seccomp "
    "profile that allows unshare and mount), so the full disk is not tested: ";

std::vector<std::uint8_t> random_bytes(std::size_t size, unsigned seed) {
  std::mt19937 rng(seed);
  std::vector<std::uint8_t> bytes(size);
  for (auto& b : bytes) b = static_cast<std::uint8_t>(rng());
  return bytes;
}

std::string names_in(const fs::path& folder) {
  std::string names;
  for (const auto& entry : fs::directory_iterator(folder)) {
    if (!names.empty()) names += ' ';
    names += entry.path().filename().string();
  }
  return names;
}

// A child process with its own mount namespace and a tmpfs of `size_bytes` on `dir`, which runs
// `body` there and exits. What the child writes to report() comes back through a pipe, so its
// checks reach the parent's test (an EXPECT in the child would not).
class TmpfsChild {
 public:
  TmpfsChild(const fs::path& dir, std::size_t size_bytes,
             const std::function<void(TmpfsChild&)>& body) {
    int fds[2];
    if (::pipe2(fds, O_CLOEXEC) != 0) throw std::runtime_error("pipe2 failed");
    pid_ = ::fork();
    if (pid_ < 0) throw std::runtime_error("fork failed");
    if (pid_ == 0) {
      ::close(fds[0]);
      write_fd_ = fds[1];
      // Private first: a mount in the new namespace must not propagate back to the host's.
      const std::string options = "size=" + std::to_string(size_bytes);
      if (::unshare(CLONE_NEWNS) != 0) fail_mount("unshare(CLONE_NEWNS)");
      if (::mount(nullptr, "/", nullptr, MS_REC | MS_PRIVATE, nullptr) != 0) {
        fail_mount("making / a private mount");
      }
      if (::mount("tmpfs", dir.c_str(), "tmpfs", 0, options.c_str()) != 0) {
        fail_mount("mount -t tmpfs -o " + options + " on " + dir.string());
      }
      report("mounted\n");
      body(*this);
      ::_exit(0);
    }
    ::close(fds[1]);
    read_fd_ = fds[0];
  }
  ~TmpfsChild() {
    if (pid_ > 0) {
      ::kill(pid_, SIGKILL);
      ::waitpid(pid_, nullptr, 0);
    }
    if (read_fd_ >= 0) ::close(read_fd_);
  }

  // In the child: sends text to the parent.
  void report(const std::string& text) const {
    std::size_t done = 0;
    while (done < text.size()) {
      const ssize_t n = ::write(write_fd_, text.data() + done, text.size() - done);
      if (n <= 0) return;
      done += static_cast<std::size_t>(n);
    }
  }
  // In the child, to start a program in the namespace: the pipe closes at exec.
  int report_fd() const { return write_fd_; }

  // In the parent: everything the child reported until it exited or exec'd.
  std::string reports() {
    std::string text;
    char buffer[4096];
    ssize_t n;
    while ((n = ::read(read_fd_, buffer, sizeof buffer)) > 0) text.append(buffer, n);
    return text;
  }
  // In the parent: the exit code (128 + signal when killed).
  int wait() {
    int status = 0;
    ::waitpid(pid_, &status, 0);
    pid_ = -1;
    return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
  }
  pid_t pid() const { return pid_; }

 private:
  [[noreturn]] void fail_mount(const std::string& what) {
    report("cannot mount: " + what + ": " + std::strerror(errno) + "\n");
    ::_exit(kNoMount);
  }

  pid_t pid_ = -1;
  int read_fd_ = -1, write_fd_ = -1;
};

#define SKIP_WITHOUT_ROOT()                                                                    \
  if (::geteuid() != 0) {                                                                      \
    GTEST_SKIP() << "mounting a size-limited tmpfs needs root (CI runs as root); run as root " \
                    "to test checkpoints on a full disk";                                      \
  }

TEST(CheckpointDisk, AWriteThatDoesNotFitThrowsAndLeavesThePreviousCheckpointIntact) {
  SKIP_WITHOUT_ROOT();
  indrive::testing::TempDir dir("indrive-disk");
  const fs::path folder = dir.path() / "checkpoints";
  fs::create_directories(folder);
  // Agent bytes do not compress: each checkpoint takes about 300 KB of the 512 KB file system,
  // so the first fits and the second cannot sit beside it, even for a moment.
  const auto first = pack_checkpoint({.env_steps = 100, .updates = 10}, random_bytes(300 * 1024, 1),
                                     std::vector<std::uint8_t>(64, 2));
  const auto second =
      pack_checkpoint({.env_steps = 200, .updates = 20}, random_bytes(300 * 1024, 2),
                      std::vector<std::uint8_t>(64, 2));
  TmpfsChild child(folder, 512 * 1024, [&](TmpfsChild& self) {
    CheckpointFiles files(folder, 3);
    const fs::path kept = files.save(10, first);
    self.report("after first: " + names_in(folder) + "\n");
    for (const std::uint64_t counter : {20, 10}) {  // a new name, then over the first one
      try {
        files.save(counter, second);
        self.report("save " + std::to_string(counter) + " did not throw\n");
      } catch (const IoError& error) {
        self.report("save " + std::to_string(counter) + " threw IoError: " + error.what() + "\n");
      }
      self.report("after save " + std::to_string(counter) + ": " + names_in(folder) + "\n");
    }
    self.report(std::string("first identical: ") + (read_file(kept) == first ? "yes" : "no") +
                "\n");
    std::vector<std::uint8_t> agent_bytes;
    try {
      self.report("first unpacks: env_steps " +
                  std::to_string(unpack_checkpoint(read_file(kept), agent_bytes).env_steps) + "\n");
    } catch (const std::exception& error) {
      self.report(std::string("first does not unpack: ") + error.what() + "\n");
    }
  });
  const std::string reports = child.reports();
  const int code = child.wait();
  if (code == kNoMount) GTEST_SKIP() << kNoTmpfs << reports;
  ASSERT_EQ(code, 0) << reports;
  std::printf("[figures] %zu-byte checkpoints on a 512 KiB tmpfs:\n%s", first.size(),
              reports.c_str());
  EXPECT_NE(reports.find("after first: ckpt-000000000010.bin\n"), std::string::npos) << reports;
  for (const std::string counter : {"20", "10"}) {
    EXPECT_NE(reports.find("save " + counter + " threw IoError: cannot write "), std::string::npos)
        << reports;
    EXPECT_NE(reports.find("after save " + counter + ": ckpt-000000000010.bin\n"),
              std::string::npos)
        << "no temporary file and no other checkpoint is left: " << reports;
  }
  EXPECT_NE(reports.find("No space left on device"), std::string::npos) << reports;
  EXPECT_NE(reports.find("first identical: yes"), std::string::npos) << reports;
  EXPECT_NE(reports.find("first unpacks: env_steps 100"), std::string::npos) << reports;
}

// The learner as a process, its checkpoints folder on a tmpfs that holds its first checkpoint
// (seeded before it starts) but not a second one beside it: every periodic checkpoint fails
// (checkpoint_minutes at its minimum, 0.6 s), and the learner goes on until it is stopped.
TEST(CheckpointDisk, ALearnerWhoseDiskIsFullKeepsRunningAndFailsOnlyItsFinalCheckpoint) {
  SKIP_WITHOUT_ROOT();
  indrive::testing::TempDir dir("indrive-disk");
  const fs::path config_file = dir.path() / "disk.yaml";
  std::ofstream(config_file) << indrive::testing::tiny_service_config();
  const fs::path run_dir = dir.path() / "runs" / "dtest";
  const fs::path folder = run_dir / "checkpoints";
  fs::create_directories(folder);
  const auto args = indrive::testing::service_args(
      "indrive-learner", config_file, run_dir, indrive::testing::unique_domain_id(),
      indrive::testing::source_path("deploy/dds/single_host.xml"),
      {"learner.checkpoint_minutes=0.01"});
  const auto service = service::ServiceConfig::resolve(
      {.config_file = config_file, .run_dir = run_dir, .domain_id = 0});
  const auto seed = pack_checkpoint({.env_steps = 300, .updates = 30, .policy_version = 3},
                                    agent::Agent(service.agent()).checkpoint_bytes());
  const fs::path seeded = folder / "ckpt-000000000030.bin";
  const fs::path log = dir.path() / "learner.log";

  TmpfsChild learner(folder, seed.size() * 3 / 2, [&](TmpfsChild& self) {
    try {
      CheckpointFiles(folder, 3).save(30, seed);
    } catch (const std::exception& error) {
      self.report(std::string("cannot seed the checkpoint: ") + error.what() + "\n");
      ::_exit(1);
    }
    const int out = ::open(log.c_str(), O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC, 0644);
    ::dup2(out, 1);
    ::dup2(out, 2);
    std::vector<char*> argv;
    for (const auto& arg : args) argv.push_back(const_cast<char*>(arg.c_str()));
    argv.push_back(nullptr);
    ::execv(argv[0], argv.data());
    self.report(std::string("cannot start ") + args[0] + ": " + std::strerror(errno) + "\n");
    ::_exit(127);
  });
  const std::string reports = learner.reports();  // until the exec
  if (reports.starts_with("cannot mount")) {
    learner.wait();
    GTEST_SKIP() << kNoTmpfs << reports;
  }
  ASSERT_EQ(reports, "mounted\n") << indrive::testing::slurp(log);

  // Periodic checkpoints fail and the learner keeps logging: two failures counted.
  const auto failures = [&] {
    const auto lines = indrive::testing::read_metrics(run_dir / "metrics.jsonl");
    return lines.empty() ? 0 : lines.back().value("checkpoint_failures", 0);
  };
  ASSERT_TRUE(indrive::testing::wait_until(60s, [&] { return failures() >= 2; }))
      << indrive::testing::slurp(log);
  // Its folder, as the learner sees it (inside its mount namespace): only the seeded checkpoint,
  // unchanged, and no temporary file of the failed writes.
  const fs::path inside = fs::path("/proc") / std::to_string(learner.pid()) / "root" /
                          fs::absolute(folder).relative_path();
  // A failing write in progress has its temporary there for a moment; it must go again.
  std::string names;
  EXPECT_TRUE(indrive::testing::wait_until(10s, [&] {
    names = names_in(inside);
    return names.find(".tmp") == std::string::npos;
  })) << names;
  EXPECT_NE(names.find("ckpt-000000000030.bin"), std::string::npos) << names;
  EXPECT_EQ(names.find("ckpt-000000000030.bin"), names.rfind("ckpt-")) << "one checkpoint only";
  EXPECT_EQ(read_file(inside / seeded.filename()), seed);

  ::kill(learner.pid(), SIGTERM);
  const int code = learner.wait();
  const std::string text = indrive::testing::slurp(log);
  EXPECT_EQ(code, 1) << "a final checkpoint that cannot be written is an error\n" << text;
  EXPECT_NE(text.find("No space left on device"), std::string::npos) << text;
  EXPECT_NE(text.find("the previous checkpoint " + seeded.string() + " is intact"),
            std::string::npos)
      << text;
  EXPECT_NE(text.find("final checkpoint ckpt-000000000030.bin"), std::string::npos) << text;
  EXPECT_NE(text.find("the final checkpoint could not be written"), std::string::npos) << text;
  EXPECT_NE(text.find("a restart resumes from " + seeded.string()), std::string::npos) << text;
  const auto lines = indrive::testing::read_metrics(run_dir / "metrics.jsonl");
  ASSERT_FALSE(lines.empty());
  const int counted = lines.back().value("checkpoint_failures", 0);
  EXPECT_GE(counted, 3) << "the periodic ones and the final one";
  EXPECT_EQ(lines.back().value("checkpoints", -1), 0);
  std::printf(
      "[figures] learner on a %zu-byte tmpfs with its %zu-byte checkpoint: %d checkpoint "
      "failures counted, folder '%s', exit code %d\n",
      seed.size() * 3 / 2, seed.size(), counted, names.c_str(), code);
}

}  // namespace
}  // namespace indrive::learner
