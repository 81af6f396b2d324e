// Shared pieces of the libFuzzer targets (tests/fuzz/README.md says how to build and run them).
//
// Each target decodes outside bytes the way the project does and accepts only the typed errors
// the decoder documents for bad input; any other exception, an abort (INDRIVE_CHECK), a
// sanitizer report, a leak, a hang or an allocation above libFuzzer's -malloc_limit_mb is a
// finding. Seeds come from the project's own writers: run a target with
// INDRIVE_FUZZ_WRITE_SEEDS=DIR and it writes real messages or files into DIR and exits.
//
//   extern "C" int LLVMFuzzerInitialize(int*, char***) {
//     return fuzz::initialize([](const fs::path& dir) { fuzz::write_seed(dir, "a", bytes); });
//   }
//   extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
//     fuzz::accept<ConfigError>([&] { parse(fuzz::text(data, size)); });
//     return 0;
//   }
#pragma once

#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <filesystem>
#include <fstream>
#include <functional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "indrive/basics/checksum.h"
#include "indrive/basics/log.h"

namespace indrive::fuzz {

namespace fs = std::filesystem;

// Runs `decode`; an exception of one of the Expected types is a rejection of bad input (the
// documented behaviour), any other escapes to libFuzzer, which reports it as a crash.
template <typename... Expected, typename Decode>
void accept(Decode&& decode) {
  try {
    decode();
  } catch (const std::exception& error) {
    if (!((dynamic_cast<const Expected*>(&error) != nullptr) || ...)) throw;
  }
}

inline std::string_view text(const std::uint8_t* data, std::size_t size) {
  return {reinterpret_cast<const char*>(data), size};
}

inline void write_seed(const fs::path& dir, const std::string& name,
                       std::span<const std::uint8_t> bytes) {
  std::ofstream out(dir / name, std::ios::binary);
  out.write(reinterpret_cast<const char*>(bytes.data()),
            static_cast<std::streamsize>(bytes.size()));
  if (!out) {
    std::fprintf(stderr, "fuzz: cannot write seed %s\n", (dir / name).c_str());
    std::exit(1);
  }
}

inline void write_seed(const fs::path& dir, const std::string& name, std::string_view text) {
  write_seed(dir, name, std::span(reinterpret_cast<const std::uint8_t*>(text.data()), text.size()));
}

// The whole of a file, for seeds made from shipped data.
inline std::string read_text(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

// Quiet logs (decoders log each rejection) and, when INDRIVE_FUZZ_WRITE_SEEDS names a folder,
// the target's seeds written there and the process ended.
inline int initialize(const std::function<void(const fs::path&)>& make_seeds) {
  log::set_level(log::Level::kError);
  if (const char* dir = std::getenv("INDRIVE_FUZZ_WRITE_SEEDS"); dir != nullptr && *dir != 0) {
    fs::create_directories(dir);
    make_seeds(dir);
    std::exit(0);
  }
  return 0;
}

// The file of an input whose first byte is flags: the rest, and with flag bit 0 its CRC-32
// trailer (the last 4 bytes, little-endian, over everything before them: the agent checkpoint's
// and the replay file's layout) recomputed to match the damaged content.
inline std::vector<std::uint8_t> file_with_flags(const std::uint8_t* data, std::size_t size) {
  std::vector<std::uint8_t> file(data + 1, data + size);
  if ((data[0] & 1) && file.size() >= 4) {
    const std::uint32_t crc = crc32(file.data(), file.size() - 4);
    std::memcpy(file.data() + file.size() - 4, &crc, 4);
  }
  return file;
}

// The folder of a fuzzing process's scratch files, removed when the process exits normally
// (every fuzz run left one behind on /dev/shm before).
struct ScratchDir {
  fs::path path;
  ScratchDir() {
    const fs::path base = fs::exists("/dev/shm") ? fs::path("/dev/shm") : fs::temp_directory_path();
    path = base / ("indrive-fuzz-" + std::to_string(::getpid()));
    fs::create_directories(path);
  }
  ~ScratchDir() {
    std::error_code ignored;
    fs::remove_all(path, ignored);
  }
};

// A per-process scratch file for decoders that read paths; kept on /dev/shm when it exists.
inline const fs::path& scratch_file(const std::string& suffix) {
  static const ScratchDir dir;
  static std::vector<std::pair<std::string, fs::path>> files;
  for (const auto& [name, path] : files) {
    if (name == suffix) return path;
  }
  files.emplace_back(suffix, dir.path / ("input" + suffix));
  return files.back().second;
}

inline const fs::path& as_file(const std::uint8_t* data, std::size_t size,
                               const std::string& suffix) {
  const fs::path& path = scratch_file(suffix);
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(size));
  return path;
}

}  // namespace indrive::fuzz
