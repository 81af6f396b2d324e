// A route file (YAML: name -> {loop, edges}) read and built on town01's network, as a town's
// routes are loaded.
#include <algorithm>
#include <cstdint>
#include <optional>

#include "fuzz_support.h"
#include "indrive/envserver/net.h"
#include "indrive/envserver/routes.h"
#include "indrive/envserver/town.h"

namespace {

using namespace indrive;

void make_seeds(const fuzz::fs::path& dir) {
  const fuzz::fs::path routes =
      fuzz::fs::path(INDRIVE_SOURCE_DIR) / "envserver" / "data" / "routes";
  // Every shipped route file, the route sets' subfolders (left/) included.
  for (const auto& entry : fuzz::fs::recursive_directory_iterator(routes)) {
    if (!entry.is_regular_file()) continue;
    std::string name = entry.path().lexically_relative(routes).string();
    std::replace(name.begin(), name.end(), '/', '-');
    fuzz::write_seed(dir, name, fuzz::read_text(entry.path()));
  }
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) { return fuzz::initialize(make_seeds); }

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const env::RoadNetwork net = env::RoadNetwork::load(env::resolve_town_network("town01"));
  const auto& path = fuzz::as_file(data, size, ".routes.yaml");
  fuzz::accept<env::RouteError>([&] {
    const auto specs = env::read_route_file(path);
    const auto routes = env::build_routes(net, specs);
    env::route_conflicts(routes);
  });
  return 0;
}
