// Town resolution: built-in towns, user networks, OpenDRIVE conversion, procedural grids, and
// the content-hashed cache of converted networks.
#include <fcntl.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <map>
#include <random>
#include <sstream>

#include "indrive/basics/checksum.h"
#include "indrive/basics/child_signals.h"
#include "indrive/basics/data_path.h"
#include "indrive/basics/log.h"
#include "indrive/envserver/net.h"
#include "indrive/envserver/route_check.h"
#include "indrive/envserver/town.h"

extern char** environ;

namespace indrive::env {

namespace {

namespace fs = std::filesystem;

// Conversion options shared by every network we build: right-hand traffic, no U-turns, no XML
// validation (SUMO_HOME data may be absent), and node coordinates kept as written. The lane
// centres of netconvert's turns are curves, tightest mid-turn: with a junction corner radius of
// 10 m no turn is tighter than ~7.6 m, within reach of the ego's ~7.55 m turning radius
// (wheelbase 2.9 m, wheel angle 0.3 * 70 deg); 6 m would give right turns of ~5.2 m.
// clang-format off
const std::vector<std::string> kCommonOptions = {
    "--xml-validation", "never",
    "--no-turnarounds", "true",
    "--default.lanewidth", "3.5",
    "--default.junctions.radius", "10",
    "--junctions.corner-detail", "5",
    "--junctions.internal-link-detail", "8",
    "--offset.disable-normalization", "true",
    "--no-warnings", "true",
};
// clang-format on
// Bump when the conversion changes in a way the options above do not show.
constexpr const char* kCacheVersion = "net-v1";

std::string read_file(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw MapError("cannot read '" + path.string() + "'");
  std::ostringstream text;
  text << in.rdbuf();
  return text.str();
}

std::string env_or_empty(const char* name) {
  const char* value = std::getenv(name);
  return value != nullptr ? std::string(value) : std::string();
}

fs::path data_dir(const TownOptions& options) {
  if (!options.data_dir.empty()) return options.data_dir;
  if (auto env = env_or_empty("INDRIVE_ENV_DATA_DIR"); !env.empty()) return env;
  // Otherwise the shared data roots: $INDRIVE_DATA_DIR, an installed share/indrive, the
  // source tree (indrive/basics/data_path.h).
  try {
    return find_data("envserver/data");
  } catch (const DataPathError& error) {
    throw MapError(std::string("town data not found: ") + error.what());
  }
}

fs::path cache_dir(const TownOptions& options) {
  if (!options.cache_dir.empty()) return options.cache_dir;
  if (auto env = env_or_empty("INDRIVE_CACHE_DIR"); !env.empty()) return env;
  if (auto env = env_or_empty("XDG_CACHE_HOME"); !env.empty()) return fs::path(env) / "indrive";
  if (auto env = env_or_empty("HOME"); !env.empty()) return fs::path(env) / ".cache" / "indrive";
  return fs::temp_directory_path() / "indrive-cache";
}

fs::path program(const fs::path& configured, const char* built_in) {
  return configured.empty() ? fs::path(built_in) : configured;
}

// Runs a program with arguments (no shell), its output going to `log_path`; returns the exit
// status, or -1 when it could not be started.
int run_program(const std::vector<std::string>& argv, const fs::path& log_path) {
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, STDOUT_FILENO, log_path.c_str(),
                                   O_WRONLY | O_CREAT | O_TRUNC, 0644);
  posix_spawn_file_actions_adddup2(&actions, STDOUT_FILENO, STDERR_FILENO);
  std::vector<char*> args;
  args.reserve(argv.size() + 1);
  for (const auto& arg : argv) args.push_back(const_cast<char*>(arg.c_str()));
  args.push_back(nullptr);
  pid_t pid = 0;
  // A program that blocks its stop signals (an actor) must not pass the mask on.
  const ChildSignals child_signals;
  const int spawned =
      posix_spawn(&pid, args[0], &actions, child_signals.attributes(), args.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  if (spawned != 0) return -1;
  int status = 0;
  while (waitpid(pid, &status, 0) < 0) {
    if (errno != EINTR) return -1;
  }
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

std::string tail_of(const fs::path& log_path, size_t max_chars = 1500) {
  std::ifstream in(log_path);
  std::ostringstream text;
  text << in.rdbuf();
  std::string all = text.str();
  if (all.size() > max_chars) all = "..." + all.substr(all.size() - max_chars);
  return all;
}

// A normal edge shorter than this is one the ego can pass within one 0.1 s step, and SUMO's
// placement of an externally moved vehicle (moveToXY on its route) then skips it and leaves
// the vehicle on a lane its route position does not know: SUMO's sublane model asserts and
// aborts the process (CARLA's Town07 has 26 such 0.2 m edges; CARLA's Town01 and Town02
// none). Converting a map given by path joins the two junctions of each such edge into one.
constexpr double kShortEdgeM = 1.0;

// Writes a netconvert node file joining the junctions at both ends of every normal edge of
// `net` shorter than kShortEdgeM (chains of them into one junction); returns how many edges
// were short (0: nothing written). An empty `out` only counts.
int write_short_edge_joins(const fs::path& net, const fs::path& out) {
  const RoadNetwork network = RoadNetwork::load(net);
  std::map<std::string, std::string> parent;
  const auto root = [&](std::string id) {
    if (!parent.count(id)) parent[id] = id;
    while (parent[id] != id) id = parent[id];
    return id;
  };
  int short_edges = 0;
  for (const Edge& edge : network.edges()) {
    if (edge.internal || edge.from_junction.empty() || edge.to_junction.empty()) continue;
    double longest = 0.0;
    for (int lane : edge.lanes) longest = std::max(longest, network.lane(lane).length_m);
    if (longest >= kShortEdgeM) continue;
    ++short_edges;
    parent[root(edge.from_junction)] = root(edge.to_junction);
  }
  if (short_edges == 0 || out.empty()) return short_edges;
  std::map<std::string, std::vector<std::string>> groups;
  for (const auto& [id, up] : parent) groups[root(id)].push_back(id);
  std::ofstream file(out);
  file << "<nodes>\n";
  for (const auto& [group_root, ids] : groups) {
    file << "  <join nodes=\"";
    for (std::size_t i = 0; i < ids.size(); ++i) file << (i > 0 ? " " : "") << ids[i];
    file << "\"/>\n";
  }
  file << "</nodes>\n";
  if (!file) throw MapError("cannot write '" + out.string() + "'");
  return short_edges;
}

// Builds `output` with `argv` + ["-o", tmp] unless a file with the same content hash exists;
// the hash covers the inputs' bytes and the arguments. With join_short_edges, a second
// netconvert pass joins away edges shorter than kShortEdgeM (write_short_edge_joins). Safe
// when several processes race.
fs::path convert_cached(const std::string& stem, const std::vector<fs::path>& inputs,
                        std::vector<std::string> argv, const TownOptions& options,
                        bool join_short_edges = false) {
  std::uint32_t hash = indrive::crc32(kCacheVersion, std::char_traits<char>::length(kCacheVersion));
  if (join_short_edges) {
    const std::string pass = "join-short-edges-1m";
    hash = indrive::crc32(pass.data(), pass.size() + 1, hash);
  }
  for (const auto& input : inputs) {
    const std::string bytes = read_file(input);
    hash = indrive::crc32(bytes.data(), bytes.size(), hash);
  }
  for (const auto& arg : argv) {
    // Paths are not part of the key: the same content converts to the same network.
    if (std::find(inputs.begin(), inputs.end(), fs::path(arg)) != inputs.end()) continue;
    hash = indrive::crc32(arg.data(), arg.size() + 1, hash);
  }
  char hex[9];
  std::snprintf(hex, sizeof hex, "%08x", hash);
  const fs::path dir = cache_dir(options);
  fs::path output = dir / (stem + "-" + hex + ".net.xml");
  std::error_code ec;
  if (fs::is_regular_file(output, ec)) return output;

  fs::create_directories(dir, ec);
  if (ec) {
    throw MapError("cannot create the network cache folder '" + dir.string() + "' (" +
                   ec.message() + "); set INDRIVE_CACHE_DIR to a writable folder");
  }
  // Unique temporary names, renamed into place: concurrent actors never see half a file.
  std::random_device random;
  const std::string token = std::to_string(::getpid()) + "-" + std::to_string(random() % 100000);
  const fs::path temporary = dir / (stem + "-" + hex + "." + token + ".tmp.net.xml");
  const fs::path log_path = dir / (stem + "-" + hex + "." + token + ".log");
  argv.push_back("-o");
  argv.push_back(temporary.string());
  INDRIVE_LOG(kInfo, "env") << "converting " << stem << " with " << argv[0] << " into " << output;
  const int status = run_program(argv, log_path);
  if (status != 0 || !fs::is_regular_file(temporary, ec)) {
    const std::string log = tail_of(log_path);
    fs::remove(temporary, ec);
    fs::remove(log_path, ec);
    if (status == -1) {
      throw MapError("could not run '" + argv[0] +
                     "'; install SUMO (Debian package sumo) or set the program path");
    }
    throw MapError("'" + argv[0] + "' failed to convert " + stem + " (exit " +
                   std::to_string(status) + "): " + log);
  }
  if (join_short_edges) {
    const fs::path joins = dir / (stem + "-" + hex + "." + token + ".join.nod.xml");
    const int short_edges = write_short_edge_joins(temporary, joins);
    if (short_edges > 0) {
      const fs::path joined = dir / (stem + "-" + hex + "." + token + ".joined.net.xml");
      std::vector<std::string> pass = {argv[0], "--sumo-net-file", temporary.string(),
                                       "--node-files", joins.string()};
      pass.insert(pass.end(), kCommonOptions.begin(), kCommonOptions.end());
      pass.insert(pass.end(), {"-o", joined.string()});
      INDRIVE_LOG(kInfo, "env") << stem << ": joining the junctions at " << short_edges
                                << " edge(s) shorter than " << kShortEdgeM
                                << " m (SUMO cannot place the ego across them)";
      const int joined_status = run_program(pass, log_path);
      fs::remove(joins, ec);
      if (joined_status != 0 || !fs::is_regular_file(joined, ec)) {
        const std::string log = tail_of(log_path);
        fs::remove(temporary, ec);
        fs::remove(joined, ec);
        fs::remove(log_path, ec);
        throw MapError("'" + argv[0] + "' failed to join the short edges of " + stem + " (exit " +
                       std::to_string(joined_status) + "): " + log);
      }
      fs::rename(joined, temporary, ec);
    } else {
      fs::remove(joins, ec);
    }
  }
  fs::remove(log_path, ec);
  fs::rename(temporary, output, ec);
  if (ec) {
    throw MapError("cannot move the converted network into '" + output.string() +
                   "': " + ec.message());
  }
  return output;
}

bool ends_with(const std::string& text, const std::string& suffix) {
  return text.size() >= suffix.size() &&
         text.compare(text.size() - suffix.size(), suffix.size(), suffix) == 0;
}

std::string known_specs() {
  return "a built-in town (town01, town02, carla_town01, carla_town02), a .net.xml file, an "
         ".xodr file or grid:<seed>";
}

fs::path missing_builtin(const fs::path& file) {
  throw MapError("built-in town source '" + file.string() +
                 "' is missing; set INDRIVE_DATA_DIR to a folder that holds envserver/data/ "
                 "(an installed share/indrive), or INDRIVE_ENV_DATA_DIR to the "
                 "envserver/data folder itself");
}

}  // namespace

std::vector<std::string> builtin_towns() {
  return {"town01", "town02", "carla_town01", "carla_town02"};
}

bool is_builtin_town(const std::string& spec) {
  const auto towns = builtin_towns();
  return std::find(towns.begin(), towns.end(), spec) != towns.end();
}

fs::path resolve_town_network(const std::string& spec, const TownOptions& options) {
  const auto towns = builtin_towns();
  const fs::path netconvert = program(options.netconvert, INDRIVE_NETCONVERT_BINARY);
  std::error_code ec;

  if (std::find(towns.begin(), towns.end(), spec) != towns.end()) {
    const fs::path folder = data_dir(options) / "towns";
    if (spec.starts_with("carla_")) {
      // CARLA's own maps (towns/CARLA-LICENSE.txt), converted as any .xodr given by path but
      // without their traffic lights: the camera renders none and no rule judges them, so
      // traffic yields by priority at every junction, as on our towns (docs/decisions.md
      // has what the lights cost an oracle under the strict budget).
      const fs::path xodr = folder / (spec + ".xodr");
      if (!fs::is_regular_file(xodr, ec)) missing_builtin(xodr);
      std::vector<std::string> argv = {netconvert.string(), "--opendrive-files", xodr.string(),
                                       "--tls.discard-loaded", "true"};
      argv.insert(argv.end(), kCommonOptions.begin(), kCommonOptions.end());
      return convert_cached(spec, {xodr}, argv, options);
    }
    const fs::path nodes = folder / (spec + ".nod.xml");
    const fs::path edges = folder / (spec + ".edg.xml");
    for (const auto& file : {nodes, edges}) {
      if (!fs::is_regular_file(file, ec)) missing_builtin(file);
    }
    std::vector<std::string> argv = {netconvert.string(), "--node-files", nodes.string(),
                                     "--edge-files", edges.string()};
    argv.insert(argv.end(), kCommonOptions.begin(), kCommonOptions.end());
    return convert_cached(spec, {nodes, edges}, argv, options);
  }

  if (spec.rfind("grid:", 0) == 0) {
    // A procedural grid: the seed picks the number and length of blocks. Attached stubs turn
    // the grid's corners into crossings, so no corner is a tight L-bend.
    unsigned long seed = 0;
    try {
      seed = std::stoul(spec.substr(5));
    } catch (const std::exception&) {
      throw MapError("bad procedural town '" + spec + "': expected grid:<seed>, e.g. grid:7");
    }
    std::mt19937 rng(static_cast<std::uint32_t>(seed));
    const int nx = 3 + static_cast<int>(rng() % 3);
    const int ny = 3 + static_cast<int>(rng() % 3);
    const int x_length = 70 + static_cast<int>(rng() % 61);
    const int y_length = 70 + static_cast<int>(rng() % 61);
    std::vector<std::string> argv = {
        program(options.netgenerate, INDRIVE_NETGENERATE_BINARY).string(),
        "--grid",
        "--grid.x-number",
        std::to_string(nx),
        "--grid.y-number",
        std::to_string(ny),
        "--grid.x-length",
        std::to_string(x_length),
        "--grid.y-length",
        std::to_string(y_length),
        "--grid.attach-length",
        "25",
        "--default.lanenumber",
        "1",
        "--default-junction-type",
        "priority"};
    argv.insert(argv.end(), kCommonOptions.begin(), kCommonOptions.end());
    return convert_cached("grid" + std::to_string(seed), {}, argv, options);
  }

  fs::path path(spec);
  if (ends_with(spec, ".net.xml")) {
    if (!fs::is_regular_file(path, ec)) {
      throw MapError("road network file '" + spec + "' does not exist; give " + known_specs());
    }
    if (write_short_edge_joins(path, {}) == 0) return path;
    // Edges too short to place the ego across (kShortEdgeM): a cached copy with them joined.
    std::vector<std::string> argv = {netconvert.string(), "--sumo-net-file", path.string()};
    argv.insert(argv.end(), kCommonOptions.begin(), kCommonOptions.end());
    return convert_cached(path.stem().stem().string(), {path}, argv, options,
                          /*join_short_edges=*/true);
  }
  if (ends_with(spec, ".xodr")) {
    if (!fs::is_regular_file(path, ec)) {
      throw MapError("OpenDRIVE file '" + spec + "' does not exist; give " + known_specs());
    }
    std::vector<std::string> argv = {netconvert.string(), "--opendrive-files", path.string()};
    argv.insert(argv.end(), kCommonOptions.begin(), kCommonOptions.end());
    return convert_cached(path.stem().string(), {path}, argv, options, /*join_short_edges=*/true);
  }
  throw MapError("unknown town '" + spec + "'; give " + known_specs());
}

namespace {

// The route file of a built-in town.
fs::path builtin_route_file(const std::string& spec, const TownOptions& options) {
  if (!is_route_set(options.route_set)) {
    throw MapError("unknown route set '" + options.route_set + "'; give right or left");
  }
  fs::path folder = data_dir(options) / "routes";
  // The route sets are designs of our towns' routes; the CARLA towns have one set, the public
  // InDRiVE code's routes, whatever the set.
  if (options.route_set != kRouteSets.front() && !spec.starts_with("carla_")) {
    folder /= options.route_set;
  }
  return folder / (spec + ".routes.yaml");
}

}  // namespace

std::vector<std::string> town_route_names(const std::string& spec, const TownOptions& options) {
  if (!is_builtin_town(spec)) return {kRouteNames.begin(), kRouteNames.end()};
  std::vector<std::string> names;
  for (const RouteSpec& route : read_route_file(builtin_route_file(spec, options))) {
    names.push_back(route.name);
  }
  return names;
}

namespace {

// Derived routes, each one the scripted follower drives (oracle_drive_failure()), cached
// beside the converted networks under the network's content hash: the check costs once per
// map. Returns the specs; `dropped` gets one line per candidate the check refused.
std::vector<RouteSpec> checked_derived_routes(const RoadNetwork& net, const fs::path& net_file,
                                              const TownOptions& options,
                                              std::vector<std::string>& dropped) {
  constexpr const char* kRoutesVersion = "routes-v2";  // v2: crossing lanes rank below aligned ones
  const std::string bytes = read_file(net_file);
  std::uint32_t hash =
      indrive::crc32(kRoutesVersion, std::char_traits<char>::length(kRoutesVersion));
  hash = indrive::crc32(bytes.data(), bytes.size(), hash);
  char hex[9];
  std::snprintf(hex, sizeof hex, "%08x", hash);
  const fs::path dir = cache_dir(options);
  const std::string stem = net_file.stem().stem().string() + "-" + hex;
  const fs::path routes_file = dir / (stem + ".routes.yaml");
  const fs::path dropped_file = dir / (stem + ".dropped.txt");
  std::error_code ec;
  if (fs::is_regular_file(routes_file, ec) && fs::is_regular_file(dropped_file, ec)) {
    std::ifstream in(dropped_file);
    for (std::string line; std::getline(in, line);) {
      if (!line.empty()) dropped.push_back(line);
    }
    return read_route_file(routes_file);
  }
  std::vector<DroppedRoute> refused;
  std::vector<RouteSpec> specs = derive_routes(
      net, [&](const RouteSpec& spec) { return oracle_drive_failure(net, spec); }, &refused);
  for (const DroppedRoute& route : refused) {
    std::string line = route.spec.name + " candidate (";
    for (std::size_t i = 0; i < route.spec.edges.size(); ++i) {
      line += (i > 0 ? " " : "") + route.spec.edges[i];
    }
    dropped.push_back(line + "): " + route.reason);
  }
  if (!refused.empty()) {
    INDRIVE_LOG(kInfo, "env") << net_file.filename().string() << ": " << refused.size()
                              << " derived route candidate(s) the scripted follower cannot drive "
                                 "were dropped (indrive-env routes lists them)";
  }
  // Written under unique names and renamed into place, as the networks are.
  fs::create_directories(dir, ec);
  std::random_device random;
  const std::string token = std::to_string(::getpid()) + "-" + std::to_string(random() % 100000);
  const fs::path routes_tmp = dir / (stem + "." + token + ".routes.yaml");
  const fs::path dropped_tmp = dir / (stem + "." + token + ".dropped.txt");
  try {
    write_route_file(routes_tmp, specs);
    std::ofstream out(dropped_tmp);
    for (const std::string& line : dropped) out << line << '\n';
    out.close();
    if (!out) throw RouteError("cannot write '" + dropped_tmp.string() + "'");
    fs::rename(dropped_tmp, dropped_file, ec);
    fs::rename(routes_tmp, routes_file, ec);
  } catch (const std::exception& error) {
    // The cache is an optimisation: without it the check runs again next time.
    INDRIVE_LOG(kWarn, "env") << "could not cache the checked routes in " << dir << ": "
                              << error.what();
  }
  fs::remove(routes_tmp, ec);
  fs::remove(dropped_tmp, ec);
  return specs;
}

}  // namespace

Town load_town(const std::string& spec, const TownOptions& options) {
  const fs::path net_file = resolve_town_network(spec, options);
  RoadNetwork net = RoadNetwork::load(net_file);
  std::vector<RouteSpec> specs;
  std::vector<std::string> dropped;
  if (is_builtin_town(spec)) {
    specs = read_route_file(builtin_route_file(spec, options));
  } else {
    specs = checked_derived_routes(net, net_file, options, dropped);
  }
  std::vector<Route> routes = build_routes(net, specs);
  std::vector<SpawnPoint> spawns = spawn_points(net);
  return Town{
      spec, net_file, std::move(net), std::move(routes), std::move(spawns), std::move(dropped)};
}

}  // namespace indrive::env
