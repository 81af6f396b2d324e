// `indrive report`: the paper's result tables from evaluation results.
//
// Zero-shot (exploration policy) and few-shot (lane following, collision avoidance) success
// rates per town and route, averages over routes, and the seen-minus-held-out generalisation
// gap, with the episodes behind each cell and a 95% confidence interval.
//
// Averaging, as in the paper: within one training run, SR of a (town, route) cell is the
// uniform mean over the densities evaluated; the table cell is the mean over training seeds.
// The interval is a t-interval over seed means when there are 2 or more seeds, otherwise a
// Wilson score interval on the pooled episodes of the cell.
//
//   indrive report runs/disag-s0 runs/icm-s0 runs/rnd-s0 --out runs/report
#pragma once

#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "indrive/basics/episode_csv.h"
#include "indrive/envserver/routes.h"

namespace indrive::deploy {

// Success-rate statistics of one table cell, in percent.
struct CellStats {
  int episodes = 0;  // episodes behind the cell, all seeds and densities
  int successes = 0;
  int seeds = 0;    // training seeds averaged
  double sr = 0.0;  // mean over seeds of (mean over densities of per-density SR)
  double ci_low = 0.0;
  double ci_high = 0.0;
  // Mean route completion (share of the route driven, the destination or a full lap = 100),
  // averaged like sr: over episodes of a density, over densities, over seeds.
  double rc = 0.0;
  // Each training seed's SR of the cell (mean over its densities), by seed.
  std::map<int, double> seed_sr;
  double fr() const { return 100.0 - sr; }
};

// Which table a result belongs to: (protocol, eval_kind, task), e.g. ("strict", "zero_shot",
// "exploration"). Results judged by different rules never share a table.
struct TableKey {
  std::string protocol;  // strict | indrive_code (EpisodeRecord::protocol)
  std::string eval_kind;
  std::string task;
  auto operator<=>(const TableKey&) const = default;
};

struct Table {
  std::vector<std::string> methods;  // rows, in first-seen order
  std::vector<std::string> towns;    // in first-seen order
  // Our towns' four in the paper's order, then others by kind (straight, right, left, two
  // turns: the CARLA towns' straight_1, ...) and name.
  std::vector<std::string> routes;
  // [method][town][route] -> stats; missing when never evaluated.
  std::map<std::string, std::map<std::string, std::map<std::string, CellStats>>> cells;
  // [method][town][route][failure reason] -> episodes ending with it.
  std::map<std::string, std::map<std::string, std::map<std::string, std::map<std::string, int>>>>
      failures;
};

struct Report {
  std::map<TableKey, Table> tables;
  int episodes = 0;
  // Of those, episodes SUMO failed in (failure_reason env_fault): left out of every cell, as
  // they say nothing of the policy.
  int env_faults = 0;
  std::vector<std::string> runs;
};

// Aggregates records into tables. Throws std::invalid_argument if `records` is empty.
Report aggregate(const std::vector<EpisodeRecord>& records);

// Mean SR over the routes of one town for one method; NaN if that town has no cells.
double average_over_routes(const Table& table, const std::string& method, const std::string& town);

// A mean over training seeds with its 95% t-interval over the seeds' own values (seeds < 2:
// no interval, ci_low = ci_high = NaN).
struct SeedInterval {
  double mean = 0.0;
  double ci_low = 0.0;
  double ci_high = 0.0;
  int seeds = 0;
};

// The average SR over routes of one town, as a value per training seed (that seed's mean over
// the routes) and their mean with its t-interval; nullopt when the town has no cells or its
// routes were not evaluated with the same seeds (then no per-seed average exists).
std::optional<SeedInterval> average_over_routes_by_seed(const Table& table,
                                                        const std::string& method,
                                                        const std::string& town);

// The same for the gap: per seed, its average over `seen`'s routes minus over `heldout`'s.
std::optional<SeedInterval> gap_by_seed(const Table& table, const std::string& method,
                                        const std::string& seen, const std::string& heldout);

// The route choices of the towns a report covers (route_choices() of each town's routes), for
// the layout bound row: the most a policy that sees no route and picks its exit by a
// junction's layout reaches on average over the routes a table holds (envserver/routes.h).
using TownChoices = std::map<std::string, std::vector<env::RouteChoice>>;

// The choices of every town in `report` that loads (built-in towns, network files), with the
// built-in towns' route set `route_set` (env.route_set: "right" or "left"; the evaluations'
// CSVs do not record it); towns that do not load are left out (their bound cell reads "-").
// Throws std::invalid_argument for an unknown route set.
TownChoices route_choices_of(const Report& report, const std::string& route_set = "right");

// The paper's zero-shot average SR over routes (%, its Tables III-VI read as averages) for a
// method (disag, icm, rnd) in a town (carla_town01 = its Town01, carla_town02 = its Town02);
// nullopt where the paper gives none or the town is not one of its towns.
std::optional<double> paper_zero_shot_average(const std::string& method, const std::string& town);

// Renders the tables. `seen_town`/`heldout_town` name the generalisation-gap columns; towns
// in `choices` get a layout-bound row under the averages of strict tables, whose note names
// `route_set` (the set the choices were taken from); zero-shot tables show the paper's averages
// beside ours in the CARLA towns' columns.
std::string render_markdown(const Report& report, const std::string& seen_town,
                            const std::string& heldout_town, const TownChoices& choices = {},
                            const std::string& route_set = "right");
std::string render_latex(const Report& report);
std::string render_csv(const Report& report);

// Reads every results CSV under `inputs` (run directories: their eval/ folder; folders: their
// *.csv except learning curves, curve-*.csv; or files). Throws CsvError naming what was
// searched and what to do when a path does not exist or no episode is found.
std::vector<EpisodeRecord> load_results(const std::vector<std::filesystem::path>& inputs);

// 95% Wilson score interval for `successes` out of `n`, in percent.
std::pair<double, double> wilson_interval(int successes, int n);

}  // namespace indrive::deploy
