// Shared test fixtures.
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

namespace indrive::testing {

// A fresh, empty directory under the system temp folder, removed when the object dies.
class TempDir {
 public:
  explicit TempDir(const std::string& prefix = "indrive-test");
  ~TempDir();
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;
  const std::filesystem::path& path() const { return path_; }

 private:
  std::filesystem::path path_;
};

// A DDS domain id that no other test process running at the same time uses, so parallel
// ctest runs never cross-talk. All processes of one test share the id their parent picked.
int unique_domain_id();

// A thread's name and blocked-signal mask (bit N - 1 for signal N).
struct ThreadSignals {
  std::string name;
  std::uint64_t blocked = 0;
};

// Every thread of process `pid` (0: this one), from /proc/PID/task/*/status; empty when the
// process is gone.
std::vector<ThreadSignals> thread_signals(int pid = 0);

// Absolute path of a file in the source tree, e.g. source_path("deploy/dds/single_host.xml").
std::filesystem::path source_path(const std::string& relative);

// Every configuration the project ships (deploy/configs/*.yaml), sorted: the tests that check
// each recipe still resolves and still gives an environment.
std::vector<std::filesystem::path> shipped_configs();

// Runs a shell command line; returns its exit status (-1 when it did not exit normally) and
// puts what it wrote to stdout and stderr in `output`.
int run_command(const std::string& command, std::string& output);

// The message of the `Error` that `make()` throws, or "(no exception)" when it throws none.
template <typename Error, typename F>
std::string error_of(F&& make) {
  try {
    make();
  } catch (const Error& error) {
    return error.what();
  }
  return "(no exception)";
}

// Makes a run's DDS Security folder at `dir` with deploy/dds/make_security.sh; its output goes
// to `dir`.log. Throws std::runtime_error (with that output) when the script fails.
void make_security_folder(const std::filesystem::path& dir);

// Lets `role` of a security folder also publish `topic`, which no shipped role may (tests that
// make one process write both a snapshot and chunks), and signs its permissions again with the
// folder's CA. Throws std::runtime_error when it cannot.
void allow_publishing(const std::filesystem::path& dir, const std::string& role,
                      const std::string& topic);

}  // namespace indrive::testing
