// Reclaims the shared memory that processes ended by a signal leave behind.
//
// Fast DDS 2.9's shared-memory transport gives every participant a segment of its own,
// /dev/shm/fastrtps_<16 hex digits> (64 MiB in deploy/dds/single_host.xml, about 23 MiB of it
// touched), and holds an exclusive flock on its companion file fastrtps_<...>_el for as long as
// the owner lives. A clean exit removes both; a kill -9, the OOM killer or a crash does not,
// and nothing in Fast DDS removes them later, so a long run whose actors the launcher restarts
// after crashes fills /dev/shm (a RAM-backed file system) by ~23 MiB per crash. A segment whose
// lock nobody holds belongs to a dead process (`fastdds shm clean` of fastdds-tools applies the
// same rule by hand).
//
//   indrive::dds::SharedMemorySweeper sweeper;             // /dev/shm
//   auto swept = sweeper.sweep(std::chrono::steady_clock::now());   // once a minute
//
// A segment is removed only when two sweeps at least `grace` apart both found its lock free:
// a reader may still open the segment of a writer that died a moment ago to read a sample the
// writer had queued. Lock files younger than 10 s are not touched at all (their owner may be
// between creating and locking them). Port files (fastrtps_port<N>) are left alone: there is
// one per participant id and domain, Fast DDS reuses and repairs them itself.
#pragma once

#include <chrono>
#include <cstdint>
#include <filesystem>
#include <map>
#include <string>

namespace indrive::dds {

// Whether `name` (a file name, no folder) is the lock file of a Fast DDS segment:
// "fastrtps_" + 16 lowercase hex digits + "_el".
bool is_segment_lock_name(const std::string& name);

// Whether some process holds the flock of `lock_file` (tried with LOCK_EX | LOCK_NB and
// released at once); a file that cannot be opened counts as held.
bool lock_is_held(const std::filesystem::path& lock_file);

// The bytes a file occupies (allocated blocks; on /dev/shm that is memory), 0 when it is missing.
std::uintmax_t allocated_bytes(const std::filesystem::path& file);

struct SweepResult {
  int live = 0;                      // segments whose owner holds the lock (or too young to judge)
  int waiting = 0;                   // found free, removed at a later sweep if still free then
  int removed = 0;                   // segments removed by this sweep
  std::uintmax_t removed_bytes = 0;  // the memory they held (allocated_bytes)
};

class SharedMemorySweeper {
 public:
  using Clock = std::chrono::steady_clock;

  explicit SharedMemorySweeper(std::filesystem::path dir = "/dev/shm",
                               std::chrono::seconds grace = std::chrono::seconds(60));

  // Looks at every segment lock file in the folder once; see the file comment for the rule.
  SweepResult sweep(Clock::time_point now);

 private:
  std::filesystem::path dir_;
  std::chrono::seconds grace_;
  std::map<std::string, Clock::time_point> free_since_;  // lock file name -> first seen free
};

}  // namespace indrive::dds
