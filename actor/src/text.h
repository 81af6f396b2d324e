// Small text helpers of the actor library (private).
#pragma once

#include <string>
#include <vector>

namespace indrive::actor {

// The items separated by `separator`: {"a", "b"} -> "a, b".
inline std::string join(const std::vector<std::string>& items, const char* separator = ", ") {
  std::string out;
  for (const auto& item : items) {
    if (!out.empty()) out += separator;
    out += item;
  }
  return out;
}

}  // namespace indrive::actor
