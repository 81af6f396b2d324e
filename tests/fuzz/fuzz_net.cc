// A SUMO .net.xml as a town is loaded from it: parsed into lanes, edges, junctions and
// connections with their geometry and spatial index, then the four standard routes derived,
// as for a user's map given by path.
#include <cstdint>

#include "fuzz_support.h"
#include "indrive/envserver/net.h"
#include "indrive/envserver/routes.h"
#include "indrive/envserver/town.h"

namespace {

using namespace indrive;

void make_seeds(const fuzz::fs::path& dir) {
  for (const auto& town : env::builtin_towns()) {
    fuzz::write_seed(dir, town, fuzz::read_text(env::resolve_town_network(town)));
  }
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) { return fuzz::initialize(make_seeds); }

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  fuzz::accept<env::MapError, env::RouteError>([&] {
    const env::RoadNetwork net = env::RoadNetwork::parse(fuzz::text(data, size), "fuzz.net.xml");
    if (!net.lanes().empty()) env::build_routes(net, env::derive_routes(net));
  });
  return 0;
}
