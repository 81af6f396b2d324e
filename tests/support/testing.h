// Shared test fixtures.
#pragma once

#include <filesystem>
#include <string>

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

// Absolute path of a file in the source tree, e.g. source_path("deploy/dds/single_host.xml").
std::filesystem::path source_path(const std::string& relative);

// Makes a run's DDS Security folder at `dir` with deploy/dds/make_security.sh; its output goes
// to `dir`.log. Throws std::runtime_error (with that output) when the script fails.
void make_security_folder(const std::filesystem::path& dir);

// Lets `role` of a security folder also publish `topic`, which no shipped role may (tests that
// make one process write both a snapshot and chunks), and signs its permissions again with the
// folder's CA. Throws std::runtime_error when it cannot.
void allow_publishing(const std::filesystem::path& dir, const std::string& role,
                      const std::string& topic);

}  // namespace indrive::testing
