#include "indrive/basics/run_dir.h"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <nlohmann/json.hpp>

namespace indrive {
namespace fs = std::filesystem;

namespace {

std::string errno_text() { return std::strerror(errno); }

// Makes a rename in `directory` durable: without it a power loss can bring back the old name
// (or none) although the file's data were synced.
void fsync_directory(const fs::path& directory, const fs::path& path) {
  const int fd = ::open(directory.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd < 0) return;  // a folder we may write but not open for reading: nothing to sync with
  if (::fsync(fd) != 0 && errno != EINVAL && errno != ENOTSUP) {
    // EINVAL / ENOTSUP: the file system has no directory sync (and needs none).
    std::string message = "wrote " + path.string();
    message += " but cannot sync its folder: " + errno_text();
    message += " (the file may not survive a power loss; check the disk)";
    ::close(fd);
    throw IoError(message);
  }
  ::close(fd);
}

}  // namespace

void atomic_write(const fs::path& path, std::span<const std::uint8_t> bytes) {
  const fs::path directory = path.has_parent_path() ? path.parent_path() : fs::path(".");
  // Appended piece by piece: GCC 12 warns (-Wrestrict, a false positive) on "." + string.
  std::string name = ".";
  name += path.filename().string();
  name += ".tmp-";
  name += std::to_string(::getpid());
  const fs::path temporary = directory / name;
  const int fd = ::open(temporary.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) {
    throw IoError("cannot write " + temporary.string() + ": " + errno_text() +
                  " (does the folder exist and is it writable?)");
  }
  std::size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t n = ::write(fd, bytes.data() + done, bytes.size() - done);
    if (n < 0) {
      if (errno == EINTR) continue;
      const std::string reason = errno_text();
      ::close(fd);
      ::unlink(temporary.c_str());
      throw IoError("cannot write " + path.string() + ": " + reason + " (disk full?)");
    }
    done += static_cast<std::size_t>(n);
  }
  // Both run, so the descriptor is closed even when fsync fails (ENOSPC or EIO can surface
  // only here, on file systems that allocate at writeback).
  const int synced = ::fsync(fd);
  const int sync_errno = errno;
  const int closed = ::close(fd);
  if (synced != 0 || closed != 0) {
    const std::string reason = synced != 0 ? std::strerror(sync_errno) : errno_text();
    ::unlink(temporary.c_str());
    throw IoError("cannot flush " + path.string() + ": " + reason + " (disk full?)");
  }
  if (::rename(temporary.c_str(), path.c_str()) != 0) {
    const std::string reason = errno_text();
    ::unlink(temporary.c_str());
    throw IoError("cannot rename " + temporary.string() + " to " + path.string() + ": " + reason);
  }
  fsync_directory(directory, path);
}

void atomic_write(const fs::path& path, const std::string& text) {
  atomic_write(path, std::span(reinterpret_cast<const std::uint8_t*>(text.data()), text.size()));
}

std::vector<std::uint8_t> read_file(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw IoError("cannot open " + path.string() + ": " + errno_text());
  in.seekg(0, std::ios::end);
  const auto size = static_cast<std::size_t>(in.tellg());
  in.seekg(0);
  std::vector<std::uint8_t> bytes(size);
  if (!in.read(reinterpret_cast<char*>(bytes.data()), static_cast<std::streamsize>(size))) {
    throw IoError("cannot read " + path.string() + ": read stopped early");
  }
  return bytes;
}

RunDir RunDir::open_or_create(const fs::path& runs_root, const std::string& run_id) {
  if (run_id.empty()) throw std::invalid_argument("run id is empty; choose a name like 'disag-s0'");
  for (const char c : run_id) {
    const bool ok = std::isalnum(static_cast<unsigned char>(c)) || c == '-' || c == '_' || c == '.';
    if (!ok) {
      throw std::invalid_argument("run id '" + run_id + "' contains '" + std::string(1, c) +
                                  "'; use letters, digits, '-', '_' and '.'");
    }
  }
  const fs::path path = runs_root / run_id;
  std::error_code error;
  for (const char* sub : {"checkpoints", "eval", "plots", "videos"}) {
    fs::create_directories(path / sub, error);
    if (error) {
      throw IoError("cannot create run directory " + (path / sub).string() + ": " +
                    error.message());
    }
  }
  return RunDir(run_id, path);
}

CheckpointFiles::CheckpointFiles(fs::path folder, int keep)
    : folder_(std::move(folder)), keep_(keep) {
  if (keep_ < 1) throw std::invalid_argument("checkpoints to keep must be at least 1");
  std::error_code error;
  fs::create_directories(folder_, error);
  if (error) throw IoError("cannot create " + folder_.string() + ": " + error.message());
}

std::vector<fs::path> CheckpointFiles::list() const {
  std::vector<fs::path> files;
  std::error_code error;
  for (const auto& entry : fs::directory_iterator(folder_, error)) {
    const std::string name = entry.path().filename().string();
    // ckpt-<12 digits>.bin exactly; temporaries start with '.'.
    if (name.size() == 21 && name.starts_with("ckpt-") && name.ends_with(".bin") &&
        std::all_of(name.begin() + 5, name.begin() + 17, ::isdigit)) {
      files.push_back(entry.path());
    }
  }
  std::sort(files.begin(), files.end());
  return files;
}

std::optional<fs::path> CheckpointFiles::newest() const {
  auto files = list();
  if (files.empty()) return std::nullopt;
  return files.back();
}

fs::path CheckpointFiles::path(std::uint64_t counter) const {
  char name[32];
  std::snprintf(name, sizeof name, "ckpt-%012llu.bin", static_cast<unsigned long long>(counter));
  return folder_ / name;
}

fs::path CheckpointFiles::save(std::uint64_t counter, std::span<const std::uint8_t> bytes) {
  const fs::path path = this->path(counter);
  atomic_write(path, bytes);
  auto files = list();
  for (std::size_t i = 0; i + static_cast<std::size_t>(keep_) < files.size(); ++i) {
    std::error_code error;
    fs::remove(files[i], error);
  }
  return path;
}

MetricsLog::MetricsLog(const fs::path& path) : path_(path), out_(path, std::ios::app) {
  if (!out_) throw IoError("cannot open " + path.string() + " for appending: " + errno_text());
}

void MetricsLog::write(const nlohmann::json& record) {
  nlohmann::json line = record;
  if (!line.contains("time")) {
    line["time"] =
        std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
  }
  out_ << line.dump() << '\n';
  out_.flush();
  if (!out_) throw IoError("cannot append to " + path_.string() + " (disk full?)");
}

bool passed_multiple(std::int64_t before, std::int64_t now, std::int64_t every) {
  return every > 0 && now / every > before / every;
}

EpisodeStats::EpisodeStats(std::size_t window) : window_(window) {
  if (window_ == 0) throw std::invalid_argument("EpisodeStats: the window must hold an episode");
}

void EpisodeStats::add(std::int64_t steps, std::int64_t reach) {
  recent_.emplace_back(steps, reach);
  if (recent_.size() > window_) recent_.pop_front();
  ++interval_episodes_;
  interval_steps_ += steps;
  interval_reach_ += reach;
}

void EpisodeStats::write(nlohmann::json& record) {
  const std::string suffix = "_last" + std::to_string(window_);
  if (interval_episodes_ > 0) {
    const auto n = static_cast<double>(interval_episodes_);
    record["episode_length"] = static_cast<double>(interval_steps_) / n;
    record["episode_reach"] = static_cast<double>(interval_reach_) / n;
  }
  if (!recent_.empty()) {
    double steps = 0.0, reach = 0.0;
    for (const auto& [s, r] : recent_) {
      steps += static_cast<double>(s);
      reach += static_cast<double>(r);
    }
    const auto n = static_cast<double>(recent_.size());
    record["episode_length" + suffix] = steps / n;
    record["episode_reach" + suffix] = reach / n;
  }
  interval_episodes_ = interval_steps_ = interval_reach_ = 0;
}

}  // namespace indrive
