#include "indrive/dds/shm_sweeper.h"

#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <set>
#include <system_error>

namespace indrive::dds {
namespace fs = std::filesystem;

namespace {

constexpr std::string_view kSegmentPrefix = "fastrtps_";
constexpr std::string_view kLockSuffix = "_el";
constexpr std::size_t kHexDigits = 16;
// Lock files younger than this are left alone: their owner may not have locked them yet.
constexpr auto kMinLockAge = std::chrono::seconds(10);

bool is_lower_hex(char c) { return (c >= '0' && c <= '9') || (c >= 'a' && c <= 'f'); }

}  // namespace

bool is_segment_lock_name(const std::string& name) {
  if (name.size() != kSegmentPrefix.size() + kHexDigits + kLockSuffix.size()) return false;
  if (!name.starts_with(kSegmentPrefix) || !name.ends_with(kLockSuffix)) return false;
  for (std::size_t i = 0; i < kHexDigits; ++i) {
    if (!is_lower_hex(name[kSegmentPrefix.size() + i])) return false;
  }
  return true;
}

bool lock_is_held(const fs::path& lock_file) {
  const int fd = ::open(lock_file.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return true;
  const bool held = ::flock(fd, LOCK_EX | LOCK_NB) != 0;
  ::close(fd);  // closing releases a lock taken just now
  return held;
}

std::uintmax_t allocated_bytes(const fs::path& file) {
  struct stat info {};
  if (::stat(file.c_str(), &info) != 0) return 0;
  return static_cast<std::uintmax_t>(info.st_blocks) * 512u;
}

SharedMemorySweeper::SharedMemorySweeper(fs::path dir, std::chrono::seconds grace)
    : dir_(std::move(dir)), grace_(grace) {}

SweepResult SharedMemorySweeper::sweep(Clock::time_point now) {
  SweepResult result;
  std::set<std::string> seen;
  std::error_code error;
  const auto file_now = fs::file_time_type::clock::now();
  for (const auto& entry : fs::directory_iterator(dir_, error)) {
    const std::string name = entry.path().filename().string();
    if (!is_segment_lock_name(name)) continue;
    seen.insert(name);
    std::error_code stat_error;
    const auto written = fs::last_write_time(entry.path(), stat_error);
    if (stat_error || file_now - written < kMinLockAge || lock_is_held(entry.path())) {
      free_since_.erase(name);
      ++result.live;
      continue;
    }
    const auto [it, first_time] = free_since_.try_emplace(name, now);
    if (first_time || now - it->second < grace_) {
      ++result.waiting;
      continue;
    }
    const fs::path segment = dir_ / name.substr(0, name.size() - kLockSuffix.size());
    const std::uintmax_t bytes = allocated_bytes(segment);
    std::error_code remove_error;
    fs::remove(segment, remove_error);
    if (remove_error) continue;  // another user's, say: tried again at the next sweep
    fs::remove(entry.path(), remove_error);
    free_since_.erase(it);
    ++result.removed;
    result.removed_bytes += bytes;
  }
  // Forget lock files that went away by other means.
  std::erase_if(free_since_, [&](const auto& item) { return !seen.contains(item.first); });
  return result;
}

}  // namespace indrive::dds
