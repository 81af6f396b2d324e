#include "indrive/basics/data_path.h"

#include <cstdlib>
#include <system_error>

namespace indrive {

namespace fs = std::filesystem;

DataSearch process_data_search() {
  DataSearch search;
  if (const char* value = std::getenv(kDataDirEnvVar); value != nullptr) search.env_value = value;
  std::error_code error;
  const fs::path self = fs::read_symlink("/proc/self/exe", error);
  if (!error) search.executable = self;
#ifdef INDRIVE_SOURCE_DIR
  search.source_dir = INDRIVE_SOURCE_DIR;
#endif
  return search;
}

std::vector<fs::path> data_roots(const DataSearch& search) {
  // An explicit override is the only root: a typo must not fall back to another copy.
  if (!search.env_value.empty()) return {fs::path(search.env_value)};
  std::vector<fs::path> roots;
  if (!search.executable.empty()) {
    roots.push_back(
        (search.executable.parent_path() / ".." / "share" / "indrive").lexically_normal());
  }
  if (!search.source_dir.empty()) roots.push_back(search.source_dir);
  return roots;
}

fs::path find_data(const fs::path& relative, const DataSearch& search) {
  const std::vector<fs::path> roots = data_roots(search);
  std::string tried;
  for (const fs::path& root : roots) {
    const fs::path candidate = root / relative;
    std::error_code error;
    if (fs::exists(candidate, error)) return candidate;
    tried += "\n  " + candidate.string();
  }
  std::string message = "cannot find data file '" + relative.string() + "'; looked in:" +
                        (tried.empty() ? std::string("\n  (no candidate folder)") : tried) + "\n";
  if (!search.env_value.empty()) {
    message += std::string("$") + kDataDirEnvVar + " is set to '" + search.env_value +
               "': point it at a folder with deploy/ and envserver/data/ (an installed "
               "share/indrive, or the source tree), or unset it";
  } else {
    message += std::string("set $") + kDataDirEnvVar +
               " to an installed share/indrive folder or to the source tree";
  }
  throw DataPathError(message);
}

fs::path find_data(const fs::path& relative) { return find_data(relative, process_data_search()); }

fs::path own_program_folder() {
  std::error_code error;
  const fs::path self = fs::read_symlink("/proc/self/exe", error);
  return error ? fs::current_path() : self.parent_path();
}

}  // namespace indrive
