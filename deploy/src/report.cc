#include "indrive/deploy/report.h"

#include <algorithm>
#include <cmath>
#include <iomanip>
#include <limits>
#include <mutex>
#include <optional>
#include <set>
#include <sstream>
#include <stdexcept>

#include "indrive/envserver/town.h"

namespace indrive::deploy {
namespace fs = std::filesystem;

namespace {

const std::vector<std::string> kPaperRouteOrder = {"straight", "right_loop", "left_loop",
                                                   "two_turn"};
// Every failure event of envserver/events.h (event_name), in bit order.
const std::vector<std::string> kFailureOrder = {"collision", "lane_invasion", "wrong_direction",
                                                "off_road",  "stall",         "time_limit",
                                                "off_route", "out_of_lane",   "too_slow"};

// Where a route not in kPaperRouteOrder sorts: by its kind, read off its name's start.
int kind_rank(const std::string& route) {
  const std::vector<std::string> kinds = {"straight", "right", "left", "two_turn"};
  for (std::size_t i = 0; i < kinds.size(); ++i) {
    if (route.starts_with(kinds[i])) return static_cast<int>(i);
  }
  return static_cast<int>(kinds.size());
}

// Two-sided 97.5% quantile of Student's t for `dof` degrees of freedom.
double t_quantile_975(int dof) {
  static const double table[] = {0,     12.706, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365,
                                 2.306, 2.262,  2.228, 2.201, 2.179, 2.160, 2.145, 2.131,
                                 2.120, 2.110,  2.101, 2.093, 2.086, 2.080, 2.074, 2.069,
                                 2.064, 2.060,  2.056, 2.052, 2.048, 2.045, 2.042};
  if (dof < 1) return std::numeric_limits<double>::quiet_NaN();
  return dof <= 30 ? table[dof] : 1.96;
}

// Mean and 95% t-interval of per-seed values (the interval needs 2 or more).
SeedInterval seed_interval(const std::map<int, double>& values) {
  SeedInterval out;
  out.seeds = static_cast<int>(values.size());
  for (const auto& [seed, v] : values) out.mean += v;
  out.mean /= static_cast<double>(values.size());
  if (values.size() < 2) {
    out.ci_low = out.ci_high = std::numeric_limits<double>::quiet_NaN();
    return out;
  }
  double variance = 0.0;
  for (const auto& [seed, v] : values) variance += (v - out.mean) * (v - out.mean);
  variance /= static_cast<double>(values.size() - 1);
  const double half =
      t_quantile_975(out.seeds - 1) * std::sqrt(variance / static_cast<double>(values.size()));
  out.ci_low = out.mean - half;
  out.ci_high = out.mean + half;
  return out;
}

std::string fixed(double value, int digits = 1) {
  if (std::isnan(value)) return "-";
  std::ostringstream out;
  out << std::fixed << std::setprecision(digits) << value;
  return out.str();
}

std::string title_of(const TableKey& key) {
  const std::string rules = key.protocol == "indrive_code"
                                ? " (protocol indrive_code: the public InDRiVE code's rules)"
                                : " (protocol " + key.protocol + ")";
  if (key.eval_kind == "zero_shot")
    return "Zero-shot: " + key.task + " policy, all parameters frozen" + rules;
  if (key.eval_kind == "few_shot") return "Few-shot: " + key.task + rules;
  return key.eval_kind + ": " + key.task + rules;
}

// The stats of one cell, or nullptr when that method never ran that town and route.
const CellStats* find_cell(const Table& table, const std::string& method, const std::string& town,
                           const std::string& route) {
  const auto m = table.cells.find(method);
  if (m == table.cells.end()) return nullptr;
  const auto t = m->second.find(town);
  if (t == m->second.end()) return nullptr;
  const auto r = t->second.find(route);
  return r == t->second.end() ? nullptr : &r->second;
}

// eval/curve-<J>.csv files hold learning curves of a continuous evaluator.
bool is_curve_file(const fs::path& path) { return path.filename().string().starts_with("curve-"); }

void push_unique(std::vector<std::string>& list, const std::string& value) {
  if (std::find(list.begin(), list.end(), value) == list.end()) list.push_back(value);
}

}  // namespace

std::optional<double> paper_zero_shot_average(const std::string& method, const std::string& town) {
  // InDRiVE's zero-shot averages over routes, Town01 / Town02 (its abstract's tables).
  static const std::map<std::string, std::pair<double, double>> paper = {
      {"disag", {75.65, 73.20}}, {"icm", {62.58, 48.61}}, {"rnd", {68.58, 55.83}}};
  const auto it = paper.find(method);
  if (it == paper.end()) return std::nullopt;
  if (town == "carla_town01") return it->second.first;
  if (town == "carla_town02") return it->second.second;
  return std::nullopt;
}

std::pair<double, double> wilson_interval(int successes, int n) {
  if (n <= 0) return {0.0, 100.0};
  const double z = 1.959964;
  const double p = static_cast<double>(successes) / n;
  const double denominator = 1.0 + z * z / n;
  const double centre = (p + z * z / (2.0 * n)) / denominator;
  const double half = z * std::sqrt(p * (1.0 - p) / n + z * z / (4.0 * n * n)) / denominator;
  return {100.0 * std::max(0.0, centre - half), 100.0 * std::min(1.0, centre + half)};
}

Report aggregate(const std::vector<EpisodeRecord>& records) {
  if (records.empty()) throw std::invalid_argument("no episode results to report on");
  Report report;
  report.episodes = static_cast<int>(records.size());
  struct Count {
    int episodes = 0;
    int successes = 0;
    double completion = 0.0;  // sum of route_completion
  };
  // counts[table][method][town][route][seed][density]
  std::map<
      TableKey,
      std::map<std::string,
               std::map<std::string, std::map<std::string, std::map<int, std::map<int, Count>>>>>>
      counts;
  std::set<std::pair<int, std::string>> other_routes;  // (kind rank, name)
  for (const auto& r : records) {
    if (r.failure_reason == "env_fault") {
      ++report.env_faults;
      continue;
    }
    const TableKey key{r.protocol, r.eval_kind, r.task};
    Table& table = report.tables[key];
    push_unique(table.methods, r.method);
    push_unique(table.towns, r.town);
    push_unique(report.runs, r.run_id);
    auto& cell = counts[key][r.method][r.town][r.route][r.train_seed][r.density];
    ++cell.episodes;
    cell.completion += r.route_completion;
    if (r.success) {
      ++cell.successes;
    } else {
      ++table.failures[r.method][r.town][r.route]
                      [r.failure_reason.empty() ? "unknown" : r.failure_reason];
    }
    if (std::find(kPaperRouteOrder.begin(), kPaperRouteOrder.end(), r.route) ==
        kPaperRouteOrder.end()) {
      other_routes.emplace(kind_rank(r.route), r.route);
    }
  }
  for (auto& [key, table] : report.tables) {
    std::set<std::string> present;
    for (const auto& [method, towns] : counts[key]) {
      for (const auto& [town, routes] : towns) {
        for (const auto& [route, seeds] : routes) present.insert(route);
      }
    }
    for (const auto& route : kPaperRouteOrder) {
      if (present.count(route)) table.routes.push_back(route);
    }
    for (const auto& [rank, route] : other_routes) {
      if (present.count(route)) table.routes.push_back(route);
    }
    for (const auto& [method, towns] : counts[key]) {
      for (const auto& [town, routes] : towns) {
        for (const auto& [route, seeds] : routes) {
          CellStats stats;
          double rc = 0.0;
          for (const auto& [seed, densities] : seeds) {
            double sum = 0.0, completion = 0.0;
            for (const auto& [density, count] : densities) {
              sum += 100.0 * count.successes / count.episodes;
              completion += 100.0 * count.completion / count.episodes;
              stats.episodes += count.episodes;
              stats.successes += count.successes;
            }
            stats.seed_sr[seed] = sum / static_cast<double>(densities.size());
            rc += completion / static_cast<double>(densities.size());
          }
          stats.rc = rc / static_cast<double>(seeds.size());
          const SeedInterval over_seeds = seed_interval(stats.seed_sr);
          stats.seeds = over_seeds.seeds;
          stats.sr = over_seeds.mean;
          if (over_seeds.seeds >= 2) {
            stats.ci_low = std::max(0.0, over_seeds.ci_low);
            stats.ci_high = std::min(100.0, over_seeds.ci_high);
          } else {
            std::tie(stats.ci_low, stats.ci_high) =
                wilson_interval(stats.successes, stats.episodes);
          }
          table.cells[method][town][route] = stats;
        }
      }
    }
  }
  return report;
}

double average_over_routes(const Table& table, const std::string& method, const std::string& town) {
  const auto m = table.cells.find(method);
  if (m == table.cells.end()) return std::numeric_limits<double>::quiet_NaN();
  const auto t = m->second.find(town);
  if (t == m->second.end() || t->second.empty()) return std::numeric_limits<double>::quiet_NaN();
  double sum = 0.0;
  for (const auto& [route, stats] : t->second) sum += stats.sr;
  return sum / static_cast<double>(t->second.size());
}

namespace {

// Each seed's mean SR over the routes of one town; nullopt when the town has no cells or its
// cells were not evaluated with the same seeds.
std::optional<std::map<int, double>> route_means_by_seed(const Table& table,
                                                         const std::string& method,
                                                         const std::string& town) {
  const auto m = table.cells.find(method);
  if (m == table.cells.end()) return std::nullopt;
  const auto t = m->second.find(town);
  if (t == m->second.end() || t->second.empty()) return std::nullopt;
  std::map<int, double> sums;
  for (const auto& [seed, sr] : t->second.begin()->second.seed_sr) sums[seed] = 0.0;
  for (const auto& [route, stats] : t->second) {
    if (stats.seed_sr.size() != sums.size()) return std::nullopt;
    for (const auto& [seed, sr] : stats.seed_sr) {
      const auto it = sums.find(seed);
      if (it == sums.end()) return std::nullopt;
      it->second += sr;
    }
  }
  for (auto& [seed, sum] : sums) sum /= static_cast<double>(t->second.size());
  return sums;
}

// "s0 25.0 / 0.0, s1 ...": each seed's average over routes in every town of the table, in
// its column order; "-" when some town's routes were not evaluated with the same seeds.
std::string per_seed_averages(const Table& table, const std::string& method) {
  std::vector<std::map<int, double>> towns;
  for (const auto& town : table.towns) {
    auto means = route_means_by_seed(table, method, town);
    if (!means) return "-";
    towns.push_back(std::move(*means));
  }
  if (towns.empty()) return "-";
  std::string out;
  for (const auto& [seed, first] : towns.front()) {
    out += (out.empty() ? "s" : ", s") + std::to_string(seed) + " ";
    for (std::size_t i = 0; i < towns.size(); ++i) {
      const auto it = towns[i].find(seed);
      out += (i > 0 ? " / " : "") + (it == towns[i].end() ? std::string("-") : fixed(it->second));
    }
  }
  return out;
}

}  // namespace

std::optional<SeedInterval> average_over_routes_by_seed(const Table& table,
                                                        const std::string& method,
                                                        const std::string& town) {
  const auto means = route_means_by_seed(table, method, town);
  if (!means || means->empty()) return std::nullopt;
  SeedInterval out = seed_interval(*means);
  // An SR lies in [0, 100], like the cells' intervals.
  if (out.seeds >= 2)
    out.ci_low = std::max(0.0, out.ci_low), out.ci_high = std::min(100.0, out.ci_high);
  return out;
}

std::optional<SeedInterval> gap_by_seed(const Table& table, const std::string& method,
                                        const std::string& seen, const std::string& heldout) {
  const auto a = route_means_by_seed(table, method, seen);
  const auto b = route_means_by_seed(table, method, heldout);
  if (!a || !b || a->empty()) return std::nullopt;
  std::map<int, double> gaps;
  for (const auto& [seed, v] : *a) {
    const auto it = b->find(seed);
    if (it == b->end()) return std::nullopt;
    gaps[seed] = v - it->second;
  }
  if (gaps.size() != b->size()) return std::nullopt;
  SeedInterval out = seed_interval(gaps);
  if (out.seeds >= 2)
    out.ci_low = std::max(-100.0, out.ci_low), out.ci_high = std::min(100.0, out.ci_high);
  return out;
}

TownChoices route_choices_of(const Report& report, const std::string& route_set) {
  if (!env::is_route_set(route_set)) {
    std::string sets;
    for (std::string_view name : env::kRouteSets) {
      sets += sets.empty() ? std::string(name) + " (the default)" : ", " + std::string(name);
    }
    throw std::invalid_argument("unknown route set '" + route_set +
                                "': give the env.route_set the evaluations ran with, one of " +
                                sets);
  }
  // Loaded once per (route set, town) and process (a live dashboard asks on every refresh); a
  // town that does not load is remembered as such.
  static std::mutex mutex;
  static std::map<std::pair<std::string, std::string>, std::optional<std::vector<env::RouteChoice>>>
      cache;
  std::set<std::string> towns;
  for (const auto& [key, table] : report.tables)
    towns.insert(table.towns.begin(), table.towns.end());
  TownChoices choices;
  const std::lock_guard<std::mutex> lock(mutex);
  for (const std::string& name : towns) {
    const auto key = std::make_pair(route_set, name);
    auto it = cache.find(key);
    if (it == cache.end()) {
      std::optional<std::vector<env::RouteChoice>> loaded;
      try {
        env::TownOptions options;
        options.route_set = route_set;
        const env::Town town = env::load_town(name, options);
        loaded = env::route_choices(town.net, town.routes);
      } catch (const std::exception&) {
        // A town this machine cannot load (a network file elsewhere): no bound for it.
      }
      it = cache.emplace(key, std::move(loaded)).first;
    }
    if (it->second) choices[name] = *it->second;
  }
  return choices;
}

namespace {

// The pieces of render_markdown, one per section of a table.

void write_header(std::ostringstream& md, const Report& report) {
  md << "# Results\n\n"
     << report.episodes << " episodes from " << report.runs.size() << " run(s)"
     << (report.env_faults > 0
             ? " (" + std::to_string(report.env_faults) +
                   " of them ended by a SUMO fault, env_fault, and are left out of every cell)"
             : std::string())
     << ". SR = % of "
     << "successful episodes, FR = 100 - SR. Each cell: SR averaged uniformly over the "
     << "densities evaluated, then over training seeds; [95% CI] is a t-interval over seeds "
     << "when there are 2 or more, otherwise a Wilson interval on the pooled episodes; n = "
     << "episodes behind the cell. Averages over routes and gaps: with 2 or more seeds, [95% CI] "
     << "is a t-interval over the seeds' own averages (gaps), clamped to the possible range, "
     << "none with one seed; \"per seed\" lists those averages.\n";
}

// One table per town: SR with its interval, FR and n per route.
void write_route_tables(std::ostringstream& md, const Table& table) {
  for (const auto& town : table.towns) {
    // The routes evaluated in this town (the CARLA towns' differ from ours and each other).
    std::vector<std::string> routes;
    for (const auto& route : table.routes) {
      for (const auto& method : table.methods) {
        if (find_cell(table, method, town, route) != nullptr) {
          routes.push_back(route);
          break;
        }
      }
    }
    md << "\n### " << town << "\n\n| method |";
    for (const auto& route : routes) md << " " << route << " SR | FR | n |";
    md << "\n|---|";
    for (std::size_t i = 0; i < routes.size(); ++i) md << "---|---|---|";
    md << "\n";
    for (const auto& method : table.methods) {
      md << "| " << method << " |";
      for (const auto& route : routes) {
        const CellStats* s = find_cell(table, method, town, route);
        if (s == nullptr) {
          md << " - | - | 0 |";
        } else {
          md << " " << fixed(s->sr) << " [" << fixed(s->ci_low) << ", " << fixed(s->ci_high)
             << "] | " << fixed(s->fr()) << " | " << s->episodes << " |";
        }
      }
      md << "\n";
    }
  }
}

// The columns of the averages table after the towns': the gap between the towns named, or
// between their CARLA namesakes in a table of CARLA towns only (town01 -> carla_town01), and the
// per-seed averages.
struct AverageColumns {
  std::string seen_town, heldout_town;
  bool has_gap = false;
  bool several_seeds = false;
};

AverageColumns average_columns(const Table& table, const std::string& seen_name,
                               const std::string& heldout_name) {
  const auto holds = [&table](const std::string& town) {
    return std::find(table.towns.begin(), table.towns.end(), town) != table.towns.end();
  };
  const bool carla_pair = !holds(seen_name) && !holds(heldout_name) &&
                          holds("carla_" + seen_name) && holds("carla_" + heldout_name);
  AverageColumns columns;
  columns.seen_town = carla_pair ? "carla_" + seen_name : seen_name;
  columns.heldout_town = carla_pair ? "carla_" + heldout_name : heldout_name;
  columns.has_gap = holds(columns.seen_town) && holds(columns.heldout_town);
  // With two or three seeds a t-interval is wide (t = 12.7 for two) and clamped to the range;
  // each seed's own averages say more, so a table where some method has 2 or more seeds lists
  // them: "s0 25.0 / 0.0" is seed 0's average over routes in each town, in column order.
  for (const auto& method : table.methods) {
    for (const auto& town : table.towns) {
      const auto means = route_means_by_seed(table, method, town);
      columns.several_seeds = columns.several_seeds || (means && means->size() >= 2);
    }
  }
  return columns;
}

// With 2 or more seeds a cell also carries the t-interval over the seeds' own averages (and
// gaps), which is what tells two methods apart; one seed's has none.
std::string with_interval(double value, const std::optional<SeedInterval>& by_seed) {
  std::string text = fixed(value);
  if (by_seed && by_seed->seeds >= 2) {
    text += " [" + fixed(by_seed->ci_low) + ", " + fixed(by_seed->ci_high) + "]";
  }
  return text;
}

void write_average_rows(std::ostringstream& md, const Table& table, const AverageColumns& c) {
  md << "\n### Average SR over routes\n\n| method |";
  for (const auto& town : table.towns) md << " " << town << " |";
  if (c.has_gap) md << " gap (" << c.seen_town << " - " << c.heldout_town << ") |";
  if (c.several_seeds) {
    md << " per seed (";
    for (std::size_t i = 0; i < table.towns.size(); ++i) {
      md << (i > 0 ? " / " : "") << table.towns[i];
    }
    md << ") |";
  }
  md << "\n|---|";
  for (std::size_t i = 0; i < table.towns.size() + (c.has_gap ? 1 : 0) + (c.several_seeds ? 1 : 0);
       ++i) {
    md << "---|";
  }
  md << "\n";
  for (const auto& method : table.methods) {
    md << "| " << method << " |";
    for (const auto& town : table.towns) {
      md << " "
         << with_interval(average_over_routes(table, method, town),
                          average_over_routes_by_seed(table, method, town))
         << " |";
    }
    if (c.has_gap) {
      md << " "
         << with_interval(average_over_routes(table, method, c.seen_town) -
                              average_over_routes(table, method, c.heldout_town),
                          gap_by_seed(table, method, c.seen_town, c.heldout_town))
         << " |";
    }
    if (c.several_seeds) md << " " << per_seed_averages(table, method) << " |";
    md << "\n";
  }
}

// The paper's own zero-shot averages, in the columns of its towns.
void write_paper_rows(std::ostringstream& md, const Table& table, const AverageColumns& c) {
  for (const auto& method : table.methods) {
    bool any = false;
    for (const auto& town : table.towns) any = any || paper_zero_shot_average(method, town);
    if (!any) continue;
    md << "| *paper, " << method << "* |";
    for (const auto& town : table.towns) {
      const auto value = paper_zero_shot_average(method, town);
      md << " " << (value ? fixed(*value, 2) : std::string("-")) << " |";
    }
    if (c.has_gap) {
      const auto seen = paper_zero_shot_average(method, c.seen_town);
      const auto held = paper_zero_shot_average(method, c.heldout_town);
      md << " " << (seen && held ? fixed(*seen - *held, 2) : std::string("-")) << " |";
    }
    if (c.several_seeds) md << " |";
    md << "\n";
  }
}

// The layout bound is a bound of the strict rules (the route's own exits); under indrive_code a
// policy may reach the end point by any path. Over the routes this table holds: the share one
// layout -> exit rule follows.
void write_layout_bound_row(std::ostringstream& md, const TableKey& key, const Table& table,
                            const AverageColumns& c, const TownChoices& choices,
                            const std::string& route_set) {
  bool any_bound = false;
  for (const auto& town : table.towns) {
    any_bound = any_bound || (key.protocol == "strict" && choices.count(town) > 0);
  }
  if (!any_bound) return;
  md << "| *layout bound* |";
  for (const auto& town : table.towns) {
    const auto found = choices.find(town);
    if (found == choices.end()) {
      md << " - |";
      continue;
    }
    std::vector<env::RouteChoice> held;
    for (const env::RouteChoice& choice : found->second) {
      if (std::find(table.routes.begin(), table.routes.end(), choice.route) != table.routes.end()) {
        held.push_back(choice);
      }
    }
    const env::LayoutRuleBound bound = env::layout_rule_bound(table.routes, held);
    md << " "
       << fixed(100.0 * static_cast<double>(bound.routes_followed.size()) /
                static_cast<double>(bound.route_count))
       << " |";
  }
  if (c.has_gap) md << " |";
  if (c.several_seeds) md << " |";
  md << "\n\n*layout bound*: the highest average SR over these routes of a policy that sees "
        "no route and picks its exit by the exits a junction offers, on the built-in "
        "towns' route set `"
     << route_set << "` (`indrive-env routes --route-set " << route_set
     << "` lists the look-alike junctions).\n";
}

// Route completion: how far the policies get, where SR only says whether they arrive.
void write_route_completion(std::ostringstream& md, const Table& table) {
  md << "\n### Mean route completion (%)\n\n| method | town |";
  for (const auto& route : table.routes) md << " " << route << " |";
  md << " average |\n|---|---|";
  for (std::size_t i = 0; i <= table.routes.size(); ++i) md << "---|";
  md << "\n";
  for (const auto& method : table.methods) {
    for (const auto& town : table.towns) {
      md << "| " << method << " | " << town << " |";
      double sum = 0.0;
      int n = 0;
      for (const auto& route : table.routes) {
        const CellStats* s = find_cell(table, method, town, route);
        if (s == nullptr) {
          md << " - |";
          continue;
        }
        md << " " << fixed(s->rc) << " |";
        sum += s->rc;
        ++n;
      }
      md << " " << (n > 0 ? fixed(sum / n) : std::string("-")) << " |\n";
    }
  }
}

// Failure reasons per route, in kFailureOrder and then any others.
void write_failure_reasons(std::ostringstream& md, const Table& table) {
  std::set<std::string> reasons;
  for (const auto& [method, towns] : table.failures) {
    for (const auto& [town, routes] : towns) {
      for (const auto& [route, counts] : routes) {
        for (const auto& [reason, n] : counts) reasons.insert(reason);
      }
    }
  }
  if (reasons.empty()) return;
  std::vector<std::string> columns;
  for (const auto& reason : kFailureOrder) {
    if (reasons.count(reason)) columns.push_back(reason);
  }
  for (const auto& reason : reasons) push_unique(columns, reason);
  md << "\n### Failure reasons (episodes)\n\n| method | town | route |";
  for (const auto& reason : columns) md << " " << reason << " |";
  md << "\n|---|---|---|";
  for (std::size_t i = 0; i < columns.size(); ++i) md << "---|";
  md << "\n";
  for (const auto& method : table.methods) {
    const auto m = table.failures.find(method);
    if (m == table.failures.end()) continue;
    for (const auto& town : table.towns) {
      const auto t = m->second.find(town);
      if (t == m->second.end()) continue;
      for (const auto& route : table.routes) {
        const auto r = t->second.find(route);
        if (r == t->second.end()) continue;
        md << "| " << method << " | " << town << " | " << route << " |";
        for (const auto& reason : columns) {
          const auto count = r->second.find(reason);
          md << " " << (count == r->second.end() ? 0 : count->second) << " |";
        }
        md << "\n";
      }
    }
  }
}

}  // namespace

std::string render_markdown(const Report& report, const std::string& seen_name,
                            const std::string& heldout_name, const TownChoices& choices,
                            const std::string& route_set) {
  std::ostringstream md;
  write_header(md, report);
  for (const auto& [key, table] : report.tables) {
    md << "\n## " << title_of(key) << "\n";
    write_route_tables(md, table);
    const AverageColumns columns = average_columns(table, seen_name, heldout_name);
    write_average_rows(md, table, columns);
    if (key.eval_kind == "zero_shot") write_paper_rows(md, table, columns);
    write_layout_bound_row(md, key, table, columns, choices, route_set);
    write_route_completion(md, table);
    write_failure_reasons(md, table);
  }
  return md.str();
}

std::string render_csv(const Report& report) {
  std::ostringstream csv;
  csv << "protocol,eval_kind,task,method,town,route,seeds,episodes,successes,sr,fr,ci_low,ci_high,"
         "rc\n";
  for (const auto& [key, table] : report.tables) {
    for (const auto& method : table.methods) {
      for (const auto& town : table.towns) {
        for (const auto& route : table.routes) {
          const CellStats* cell = find_cell(table, method, town, route);
          if (cell == nullptr) continue;
          const CellStats& s = *cell;
          csv << key.protocol << ',' << key.eval_kind << ',' << key.task << ',' << method << ','
              << town << ',' << route << ',' << s.seeds << ',' << s.episodes << ',' << s.successes
              << ',' << fixed(s.sr, 3) << ',' << fixed(s.fr(), 3) << ',' << fixed(s.ci_low, 3)
              << ',' << fixed(s.ci_high, 3) << ',' << fixed(s.rc, 3) << '\n';
        }
      }
    }
  }
  return csv.str();
}

std::string render_latex(const Report& report) {
  auto escape = [](const std::string& text) {
    std::string out;
    for (const char c : text) {
      if (c == '_' || c == '%' || c == '&' || c == '#') out += '\\';
      out += c;
    }
    return out;
  };
  std::ostringstream tex;
  for (const auto& [key, table] : report.tables) {
    for (const auto& town : table.towns) {
      tex << "% " << title_of(key) << ", " << town << "\n\\begin{tabular}{l";
      for (std::size_t i = 0; i < table.routes.size(); ++i) tex << "rr";
      tex << "}\n\\hline\nMethod";
      for (const auto& route : table.routes)
        tex << " & \\multicolumn{2}{c}{" << escape(route) << "}";
      tex << " \\\\\n";
      for (std::size_t i = 0; i < table.routes.size(); ++i) tex << " & SR & FR";
      tex << " \\\\\n\\hline\n";
      for (const auto& method : table.methods) {
        tex << escape(method);
        for (const auto& route : table.routes) {
          const CellStats* s = find_cell(table, method, town, route);
          if (s == nullptr) {
            tex << " & -- & --";
          } else {
            tex << " & " << fixed(s->sr) << " & " << fixed(s->fr());
          }
        }
        tex << " \\\\\n";
      }
      tex << "\\hline\n\\end{tabular}\n\n";
    }
  }
  return tex.str();
}

std::vector<EpisodeRecord> load_results(const std::vector<fs::path>& inputs) {
  if (inputs.empty()) throw CsvError("no results given: name run directories or CSV files");
  std::vector<fs::path> files;
  for (const auto& input : inputs) {
    if (fs::is_regular_file(input)) {
      files.push_back(input);
      continue;
    }
    if (!fs::is_directory(input)) {
      std::string message = "results path ";
      message += input.string();
      message +=
          " does not exist; name a run directory (runs/<run_id>), its eval/ folder or a "
          "results CSV";
      throw CsvError(message);
    }
    const fs::path folder = fs::is_directory(input / "eval") ? input / "eval" : input;
    std::vector<fs::path> found;
    for (const auto& entry : fs::directory_iterator(folder)) {
      if (!entry.is_regular_file() || entry.path().extension() != ".csv") continue;
      // Learning curves (continuous evaluation) have their own columns and are not tables.
      if (is_curve_file(entry.path())) continue;
      found.push_back(entry.path());
    }
    std::sort(found.begin(), found.end());
    files.insert(files.end(), found.begin(), found.end());
  }
  std::vector<EpisodeRecord> records;
  std::size_t training = 0;
  for (const auto& file : files) {
    // Training episodes (train-episodes.csv) are no evaluation: `indrive episodes` reads them.
    for (EpisodeRecord& record : read_episode_csv(file)) {
      if (record.eval_kind == "training") {
        ++training;
      } else {
        records.push_back(std::move(record));
      }
    }
  }
  if (records.empty()) {
    std::string message = "no episode results found in";
    for (const auto& input : inputs) {
      message += ' ';
      message += input.string();
    }
    if (training > 0) {
      message += " (only " + std::to_string(training) +
                 " training episodes, which `indrive episodes` summarises)";
    }
    message += "; run an evaluation first (indrive-actor --evaluate writes <run>/eval/*.csv)";
    throw CsvError(message);
  }
  return records;
}

}  // namespace indrive::deploy
