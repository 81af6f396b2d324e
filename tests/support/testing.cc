#include "testing.h"

#include <unistd.h>

#include <atomic>
#include <random>
#include <stdexcept>
#include <system_error>

namespace indrive::testing {

TempDir::TempDir(const std::string& prefix) {
  std::random_device device;
  const auto base = std::filesystem::temp_directory_path();
  for (int attempt = 0; attempt < 100; ++attempt) {
    auto candidate = base / (prefix + "-" + std::to_string(::getpid()) + "-" +
                             std::to_string(device() % 1000000));
    std::error_code error;
    if (std::filesystem::create_directories(candidate, error)) {
      path_ = std::move(candidate);
      return;
    }
  }
  throw std::runtime_error("could not create a temporary directory under " + base.string());
}

TempDir::~TempDir() {
  std::error_code error;
  std::filesystem::remove_all(path_, error);
}

int unique_domain_id() {
  // Domain ids 0..232 are valid; keep 0 free for users and spread test processes by pid.
  static std::atomic<int> offset{0};
  return 1 + static_cast<int>((::getpid() * 7 + offset.fetch_add(1)) % 200);
}

std::filesystem::path source_path(const std::string& relative) {
  return std::filesystem::path(INDRIVE_SOURCE_DIR) / relative;
}

}  // namespace indrive::testing
