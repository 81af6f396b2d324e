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

}  // namespace indrive::testing
