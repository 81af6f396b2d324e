// An OpenDRIVE .xodr given by path is loaded as a user's map is (env::load_town): converted by
// netconvert, with the second pass that joins sub-metre edges, parsed, its four routes derived
// and each candidate driven by the scripted follower. netconvert runs as a child process, so a
// fault of its own comes back as a MapError with its message; a hang of it is a finding here
// (libFuzzer's -timeout), as it would hang a user's evaluator. Each input takes a conversion
// (tens of milliseconds for the seeds), so the target makes few executions a second.
#include <cstdint>
#include <cstdlib>

#include "fuzz_support.h"
#include "indrive/envserver/net.h"
#include "indrive/envserver/routes.h"
#include "indrive/envserver/town.h"

namespace {

using namespace indrive;

// Our two small towns exported to OpenDRIVE by netconvert (kilobytes, where CARLA's towns are
// a megabyte each and would spend the run converting their seeds).
void make_seeds(const fuzz::fs::path& dir) {
  for (const char* town : {"town01", "town02"}) {
    const fuzz::fs::path out = dir / (std::string(town) + ".xodr");
    const std::string command = std::string(INDRIVE_NETCONVERT) + " --xml-validation never -s " +
                                env::resolve_town_network(town).string() + " --opendrive-output " +
                                out.string() + " > /dev/null 2>&1";
    if (std::system(command.c_str()) != 0) {
      std::fprintf(stderr, "fuzz: could not export %s as OpenDRIVE: %s\n", town, command.c_str());
      std::exit(1);
    }
  }
}

// A scratch cache per process, emptied after each input: conversions are cached by content hash,
// and every input is new content.
const env::TownOptions& options() {
  static const env::TownOptions options{.cache_dir = fuzz::scratch_file(".cache")};
  return options;
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) { return fuzz::initialize(make_seeds); }

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const fuzz::fs::path& file = fuzz::as_file(data, size, ".xodr");
  fuzz::accept<env::MapError, env::RouteError>([&] { env::load_town(file.string(), options()); });
  std::error_code ignored;
  fuzz::fs::remove_all(options().cache_dir, ignored);
  return 0;
}
