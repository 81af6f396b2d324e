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

// The comma-separated items of `text`, spaces around each trimmed, empty items dropped:
// "a, b,,c" -> {"a", "b", "c"}.
inline std::vector<std::string> split_list(const std::string& text) {
  std::vector<std::string> items;
  std::size_t start = 0;
  while (start <= text.size()) {
    std::size_t comma = text.find(',', start);
    if (comma == std::string::npos) comma = text.size();
    const std::string item = text.substr(start, comma - start);
    const auto begin = item.find_first_not_of(' ');
    const auto end = item.find_last_not_of(' ');
    if (begin != std::string::npos) items.push_back(item.substr(begin, end - begin + 1));
    start = comma + 1;
  }
  return items;
}

}  // namespace indrive::actor
