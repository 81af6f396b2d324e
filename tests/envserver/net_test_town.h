// Built-in towns for the net tests, converted once into a cache inside the build tree so the
// test processes that ctest starts share one conversion.
#pragma once

#include <map>
#include <string>

#include "indrive/envserver/town.h"

namespace indrive::env::testing {

// Options that put converted networks under the test build folder.
inline TownOptions test_town_options() {
  TownOptions options;
  options.cache_dir = std::filesystem::path(INDRIVE_TEST_BINARY_DIR) / "town-cache";
  return options;
}

// Loads a town once per process.
inline const Town& cached_town(const std::string& name) {
  static std::map<std::string, Town> towns;
  auto it = towns.find(name);
  if (it == towns.end()) it = towns.emplace(name, load_town(name, test_town_options())).first;
  return it->second;
}

}  // namespace indrive::env::testing
