// The evaluation protocol grid: which episodes an evaluator runs.
//
// The paper evaluates every (town, route, density) cell with N episodes, drawing traffic seeds
// from a fixed set of 3 and spawn seeds from a fixed set of 5, so every method meets exactly
// the same traffic. Episode i of a cell uses traffic seed i mod 3 and spawn seed i mod 5 of
// those sets (all 15 pairs appear once in every 15 episodes) and policy seed i, so a sampling
// policy does not repeat an episode when a seed pair comes round again.
//
// Several evaluators split one grid without overlap: the episodes, in grid order, are dealt
// round-robin, so evaluator k of M runs episodes k, k + M, k + 2M, ...
//
//   ProtocolGrid grid{.towns = {"town01", "town02"}, .episodes_per_cell = 50};
//   for (const EpisodeSpec& e : grid.episodes_for(/*evaluator=*/0, /*of=*/2)) { ... }
#pragma once

#include <array>
#include <cstdint>
#include <map>
#include <stdexcept>
#include <string>
#include <vector>

namespace indrive::actor {

// A bad evaluator input (unknown town, route, policy or head; unreadable snapshot file; a
// snapshot without the head asked for). The message names the value and what is allowed.
class EvalError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Which rules judge an evaluation episode (eval.protocol; docs/evaluation.md, "Two protocols"):
//   strict        ours: the route's own step budget, every road rule ends the episode, leaving
//                 the route (off_route) too; success within 10 m of the route's end
//   indrive_code  the public InDRiVE code's: a fixed step budget (eval.indrive_code_budget_steps,
//                 the code's 30,000), success within 2.0 m of the end point by any path, and
//                 only collision, out of lane, off road, wrong direction and too slow end an
//                 episode (envserver/events.h); lane invasions are counted, not terminal
enum class EvalProtocol { kStrict, kIndriveCode };
// "strict" or "indrive_code".
const char* protocol_name(EvalProtocol protocol);
// Parses a protocol name; throws EvalError naming the allowed values.
EvalProtocol parse_protocol(const std::string& name);

// The fixed seed sets of the protocol (any fixed values serve; these are ours).
inline constexpr std::array<int, 3> kTrafficSeeds = {101, 202, 303};
inline constexpr std::array<int, 5> kSpawnSeeds = {11, 22, 33, 44, 55};

// One episode to evaluate.
struct EpisodeSpec {
  std::string town;
  std::string route;
  int density = 0;
  int episode = 0;  // index within its cell
  int traffic_seed = 0;
  int spawn_seed = 0;
  std::uint64_t policy_seed = 0;
  int global_index = 0;  // position in the whole grid, stable across evaluators
};

struct ProtocolGrid {
  std::vector<std::string> towns = {"town01", "town02"};
  std::vector<std::string> routes = {"straight", "right_loop", "left_loop", "two_turn"};
  // A town's own routes where they differ from `routes` (eval.routes: all names each town's
  // routes; the CARLA towns have the public code's, not our four).
  std::map<std::string, std::vector<std::string>> town_routes;
  // The routes evaluated on `town`.
  const std::vector<std::string>& routes_of(const std::string& town) const;
  std::vector<int> densities = {5, 10, 20};
  int episodes_per_cell = 50;

  // Throws std::invalid_argument naming the problem: an empty list, a density outside
  // {5, 10, 20}, a duplicate, or episodes_per_cell < 1.
  void validate() const;
  // Every episode of the grid in order: town, route, density, then episode index.
  std::vector<EpisodeSpec> all_episodes() const;
  // The episodes evaluator `index` of `count` runs (round-robin deal, no overlap).
  std::vector<EpisodeSpec> episodes_for(int index, int count) const;
  // Number of episodes in the whole grid.
  int size() const;
};

// A town as part of a file name (result CSVs, videos): a built-in town's name as it is, a map
// given by path its file's stem with anything but letters, digits, '_' and '-' made '_'
// ("maps/x.xodr" -> "x", "../my town.net.xml" -> "my_town_net").
std::string town_file_label(const std::string& town);

}  // namespace indrive::actor
