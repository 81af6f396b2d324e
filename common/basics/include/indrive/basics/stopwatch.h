// Elapsed wall time on the steady clock, for logs, pacing and benchmarks.
//
//   const auto start = SteadyClock::now();
//   ...
//   INDRIVE_LOG(kInfo, "x") << "took " << seconds_since(start) << " s";
#pragma once

#include <chrono>

namespace indrive {

using SteadyClock = std::chrono::steady_clock;

// Seconds from `start` to now.
inline double seconds_since(SteadyClock::time_point start) {
  return std::chrono::duration<double>(SteadyClock::now() - start).count();
}

}  // namespace indrive
