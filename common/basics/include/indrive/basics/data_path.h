// Where the shipped, read-only data lives: DDS profiles (deploy/dds/), run configurations
// (deploy/configs/) and town sources (envserver/data/). A data root is a folder with the same
// layout as the source tree, so one relative path names a file everywhere.
//
// Lookup order (the first root that holds the file wins):
//   1. $INDRIVE_DATA_DIR, when set: the only root consulted, so a wrong value fails loudly
//      instead of silently falling back to another copy;
//   2. <folder of the executable>/../share/indrive, the layout `cmake --install` writes;
//   3. the source tree the program was built from, for builds run in place.
//
//   std::filesystem::path xml = indrive::find_data("deploy/dds/single_host.xml");
#pragma once

#include <filesystem>
#include <stdexcept>
#include <string>
#include <vector>

namespace indrive {

// A data file was found under none of the roots; the message lists where it was looked for.
class DataPathError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Name of the environment variable that overrides every other data root.
inline constexpr const char* kDataDirEnvVar = "INDRIVE_DATA_DIR";

// Inputs of the lookup, separated from the process so that tests can pin them.
struct DataSearch {
  std::string env_value;             // value of $INDRIVE_DATA_DIR; empty: unset
  std::filesystem::path executable;  // path of the running executable; empty: unknown
  std::filesystem::path source_dir;  // source tree compiled in; empty: none
};

// The lookup inputs of this process: the environment, /proc/self/exe and the source tree.
DataSearch process_data_search();

// The candidate data roots for `search`, in lookup order.
std::vector<std::filesystem::path> data_roots(const DataSearch& search);

// Returns root/relative for the first candidate root where that path exists (file or folder);
// throws DataPathError naming every place it tried and how to point at the data.
std::filesystem::path find_data(const std::filesystem::path& relative, const DataSearch& search);

// find_data with this process's lookup inputs.
std::filesystem::path find_data(const std::filesystem::path& relative);

// The folder of the running executable (where the project's other programs are installed and
// built beside it); the current folder when /proc/self/exe cannot be read.
std::filesystem::path own_program_folder();

}  // namespace indrive
