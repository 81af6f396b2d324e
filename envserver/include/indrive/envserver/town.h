// Towns: where a road network comes from, and everything derived from it in one object.
//
// A town spec is one of
//   - a built-in name: `town01` (training town, ~400 x 330 m, T-junctions, one lane per
//     direction) or `town02` (held-out town, ~200 x 200 m, smaller blocks), our own designs;
//     `carla_town01` or `carla_town02`, CARLA's Town01 and Town02 (the paper's towns, shipped as
//     OpenDRIVE under their MIT licence, envserver/data/towns/CARLA-LICENSE.txt) with the public
//     InDRiVE code's point-to-point routes;
//   - a path to a SUMO `.net.xml`;
//   - a path to an OpenDRIVE `.xodr`, converted by netconvert;
//   - `grid:<seed>`, a procedural grid town made by netgenerate.
// Built-in towns are written as SUMO plain XML under envserver/data/towns/ and converted by
// netconvert on first use; conversions are cached by content hash, so later loads (and other
// processes) reuse them.
//
//   Town town = load_town("town01");   // throws MapError / RouteError with what to do
//   const Route& route = find_route(town.routes, "right_loop");
//   draw_town(town.net, town.routes, town.spawns, "town01.png");
#pragma once

#include <algorithm>
#include <array>
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include "indrive/envserver/net.h"
#include "indrive/envserver/routes.h"
#include "indrive/envserver/scene_build.h"

namespace indrive::env {

// Where town sources and converted networks live.
struct TownOptions {
  // Folder with towns/ and routes/; empty: $INDRIVE_ENV_DATA_DIR, else envserver/data under
  // the data roots of indrive/basics/data_path.h ($INDRIVE_DATA_DIR, installed, source tree).
  std::filesystem::path data_dir;
  // Folder for converted networks; empty: $INDRIVE_CACHE_DIR, else $XDG_CACHE_HOME/indrive,
  // else ~/.cache/indrive, else the system temp folder.
  std::filesystem::path cache_dir;
  // netconvert / netgenerate programs; empty: the ones found at build time.
  std::filesystem::path netconvert;
  std::filesystem::path netgenerate;
  // Route set of the built-in towns (routes/ for "right", routes/<set>/ otherwise): "right"
  // ships routes one layout rule follows with straight and right_loop, "left" the mirror
  // design (straight and left_loop); see kRouteSets and docs/decisions.md.
  std::string route_set = "right";
};

// The route sets of the built-in towns, the default first.
inline constexpr std::array<std::string_view, 2> kRouteSets = {"right", "left"};
// Whether `name` is one of kRouteSets.
inline bool is_route_set(std::string_view name) {
  return std::find(kRouteSets.begin(), kRouteSets.end(), name) != kRouteSets.end();
}

// The built-in town names.
std::vector<std::string> builtin_towns();
// True when `spec` is one of them.
bool is_builtin_town(const std::string& spec);

// Returns the path of a .net.xml for a town spec, converting and caching as needed. Throws
// MapError when the spec names nothing that exists or conversion fails (with netconvert's
// message).
std::filesystem::path resolve_town_network(const std::string& spec,
                                           const TownOptions& options = {});

// A loaded town: the network, its four routes and its spawn points.
struct Town {
  std::string name;  // the spec it was loaded from
  std::filesystem::path net_file;
  RoadNetwork net;
  std::vector<Route> routes;  // in file order (kRouteNames order for our towns and derived ones)
  std::vector<SpawnPoint> spawns;
  // Derived towns only: the route candidates the scripted follower could not drive, each as
  // "<kind> candidate (<edges>): <why>" (route_check.h).
  std::vector<std::string> dropped_routes;
};

// Resolves, parses and prepares a town: built-in towns read their shipped route file, others
// derive their routes from the network, keeping only routes the scripted follower drives
// alone (route_check.h; the result is cached with the converted networks). Throws MapError or
// RouteError.
Town load_town(const std::string& spec, const TownOptions& options = {});

// The route names of a town without loading its network: a built-in town's from its route
// file, the four kRouteNames for any other. Throws MapError or RouteError.
std::vector<std::string> town_route_names(const std::string& spec, const TownOptions& options = {});

// Draws the network (lanes, junctions), the routes (one colour each, with start marker and
// direction arrows) and the spawn points to a PNG at `pixels_per_m`; throws MapError when the
// file cannot be written.
void draw_town(const RoadNetwork& net, const std::vector<Route>& routes,
               const std::vector<SpawnPoint>& spawns, const std::filesystem::path& png_path,
               double pixels_per_m = 2.5);

}  // namespace indrive::env
