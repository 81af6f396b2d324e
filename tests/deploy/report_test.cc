#include "indrive/deploy/report.h"

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>

#include "testing.h"

namespace indrive::deploy {
namespace {

// n episodes of one cell, the first `successes` of them successful.
void add_episodes(std::vector<EpisodeRecord>& out, const std::string& method, int seed,
                  const std::string& town, const std::string& route, int density, int n,
                  int successes, const std::string& failure = "collision",
                  const std::string& protocol = "strict") {
  for (int i = 0; i < n; ++i) {
    out.push_back({.run_id = method + "-s" + std::to_string(seed),
                   .method = method,
                   .eval_kind = "zero_shot",
                   .task = "exploration",
                   .train_seed = seed,
                   .town = town,
                   .route = route,
                   .density = density,
                   .episode = i,
                   .success = i < successes,
                   .failure_reason = i < successes ? "" : failure,
                   .protocol = protocol});
  }
}

TEST(Report, AveragesUniformlyOverDensitiesThenSeeds) {
  std::vector<EpisodeRecord> records;
  // Seed 0: density 5 -> 4/4 = 100 %, density 20 -> 1/2 = 50 %  => 75 % (pooled would be 83 %).
  add_episodes(records, "disag", 0, "town01", "straight", 5, 4, 4);
  add_episodes(records, "disag", 0, "town01", "straight", 20, 2, 1);
  // Seed 1: density 5 -> 1/2 = 50 %, density 20 -> 0/2 = 0 %     => 25 %.
  add_episodes(records, "disag", 1, "town01", "straight", 5, 2, 1);
  add_episodes(records, "disag", 1, "town01", "straight", 20, 2, 0);
  const Report report = aggregate(records);
  const Table& table = report.tables.at({"strict", "zero_shot", "exploration"});
  const CellStats& cell = table.cells.at("disag").at("town01").at("straight");
  EXPECT_EQ(cell.episodes, 10);
  EXPECT_EQ(cell.successes, 6);
  EXPECT_EQ(cell.seeds, 2);
  EXPECT_DOUBLE_EQ(cell.sr, 50.0);
  EXPECT_DOUBLE_EQ(cell.fr(), 50.0);
  // t-interval over seed means {75, 25}: sd = 35.355, half = 12.706 * 35.355 / sqrt(2) = 317.6,
  // clipped to [0, 100].
  EXPECT_DOUBLE_EQ(cell.ci_low, 0.0);
  EXPECT_DOUBLE_EQ(cell.ci_high, 100.0);
  EXPECT_EQ(table.failures.at("disag").at("town01").at("straight").at("collision"), 4);
}

// Episodes SUMO failed in say nothing of the policy: counted, and left out of every cell.
TEST(Report, EnvFaultEpisodesAreCountedApartFromTheCells) {
  std::vector<EpisodeRecord> records;
  add_episodes(records, "disag", 0, "town01", "straight", 5, 4, 3);
  add_episodes(records, "disag", 0, "town01", "straight", 5, 2, 0, "env_fault");
  const Report report = aggregate(records);
  EXPECT_EQ(report.episodes, 6);
  EXPECT_EQ(report.env_faults, 2);
  const Table& table = report.tables.at({"strict", "zero_shot", "exploration"});
  const CellStats& cell = table.cells.at("disag").at("town01").at("straight");
  EXPECT_EQ(cell.episodes, 4);
  EXPECT_DOUBLE_EQ(cell.sr, 75.0);
  EXPECT_EQ(table.failures.at("disag").at("town01").at("straight").count("env_fault"), 0u);
}

TEST(Report, WilsonIntervalMatchesTheFormula) {
  // 8 of 10: centre (0.8 + 1.92/10) / 1.384 = 0.7168, half 0.2271 -> [49.0, 94.3] %.
  const auto [low, high] = wilson_interval(8, 10);
  EXPECT_NEAR(low, 49.02, 0.05);
  EXPECT_NEAR(high, 94.33, 0.05);
  const auto [zero_low, zero_high] = wilson_interval(0, 50);
  EXPECT_DOUBLE_EQ(zero_low, 0.0);
  EXPECT_NEAR(zero_high, 7.13, 0.05);
}

// With several seeds the average over routes and the gap carry a t-interval over the seeds' own
// averages (each seed: mean of its route cells); one seed's carry none.
TEST(Report, AveragesAndGapsCarryATIntervalOverSeeds) {
  std::vector<EpisodeRecord> records;
  // Per seed, SR of (town01 straight, two_turn; town02 straight, two_turn), 4 episodes each.
  const int successes[3][4] = {{4, 2, 2, 0}, {3, 2, 2, 2}, {2, 2, 3, 1}};
  for (int seed = 0; seed < 3; ++seed) {
    add_episodes(records, "disag", seed, "town01", "straight", 10, 4, successes[seed][0]);
    add_episodes(records, "disag", seed, "town01", "two_turn", 10, 4, successes[seed][1]);
    add_episodes(records, "disag", seed, "town02", "straight", 10, 4, successes[seed][2]);
    add_episodes(records, "disag", seed, "town02", "two_turn", 10, 4, successes[seed][3]);
  }
  add_episodes(records, "icm", 0, "town01", "straight", 10, 4, 1);
  add_episodes(records, "icm", 0, "town01", "two_turn", 10, 4, 1);
  add_episodes(records, "icm", 0, "town02", "straight", 10, 4, 0);
  add_episodes(records, "icm", 0, "town02", "two_turn", 10, 4, 0);
  const Report report = aggregate(records);
  const Table& table = report.tables.at({"strict", "zero_shot", "exploration"});
  // town01 averages per seed 75, 62.5, 50: mean 62.5, sd 12.5, half 4.303 * 12.5 / sqrt(3).
  const auto town01 = average_over_routes_by_seed(table, "disag", "town01");
  ASSERT_TRUE(town01.has_value());
  EXPECT_EQ(town01->seeds, 3);
  EXPECT_DOUBLE_EQ(town01->mean, 62.5);
  const double half = 4.303 * 12.5 / std::sqrt(3.0);
  EXPECT_NEAR(town01->ci_low, 62.5 - half, 1e-9);
  EXPECT_NEAR(town01->ci_high, 62.5 + half, 1e-9);
  // Gaps per seed 50, 12.5, 0.
  const auto gap = gap_by_seed(table, "disag", "town01", "town02");
  ASSERT_TRUE(gap.has_value());
  EXPECT_NEAR(gap->mean, 62.5 / 3.0, 1e-9);
  const std::string md = render_markdown(report, "town01", "town02");
  EXPECT_NE(md.find("| disag | 62.5 [31.4, 93.6] | 41.7 [5.8, 77.5] | 20.8 [-43.8, 85.5] |"),
            std::string::npos)
      << md;
  EXPECT_NE(md.find("| icm | 25.0 | 0.0 | 25.0 |"), std::string::npos) << md;
  // Each seed's own averages (town01 / town02: 75 / 25, 62.5 / 50, 50 / 50), and the one-seed
  // method's too.
  EXPECT_NE(
      md.find("| gap (town01 - town02) | per seed (town01 / town02) |\n|---|---|---|---|---|"),
      std::string::npos)
      << md;
  EXPECT_NE(md.find("20.8 [-43.8, 85.5] | s0 75.0 / 25.0, s1 62.5 / 50.0, s2 50.0 / 50.0 |"),
            std::string::npos)
      << md;
  EXPECT_NE(md.find("| icm | 25.0 | 0.0 | 25.0 | s0 25.0 / 0.0 |"), std::string::npos) << md;
  // Routes evaluated with different seeds have no per-seed average.
  add_episodes(records, "rnd", 0, "town01", "straight", 10, 4, 1);
  add_episodes(records, "rnd", 1, "town01", "two_turn", 10, 4, 1);
  const Report mixed = aggregate(records);
  EXPECT_FALSE(average_over_routes_by_seed(mixed.tables.at({"strict", "zero_shot", "exploration"}),
                                           "rnd", "town01")
                   .has_value());
}

TEST(Report, RoutesInPaperOrderAveragesAndTheGeneralisationGap) {
  std::vector<EpisodeRecord> records;
  add_episodes(records, "icm", 0, "town01", "two_turn", 10, 4, 1);              // 25 %
  add_episodes(records, "icm", 0, "town01", "straight", 10, 4, 3);              // 75 %
  add_episodes(records, "icm", 0, "town02", "straight", 10, 4, 2);              // 50 %
  add_episodes(records, "icm", 0, "town02", "two_turn", 10, 4, 0, "off_road");  // 0 %
  const Report report = aggregate(records);
  const Table& table = report.tables.at({"strict", "zero_shot", "exploration"});
  EXPECT_EQ(table.routes, (std::vector<std::string>{"straight", "two_turn"}));
  EXPECT_DOUBLE_EQ(average_over_routes(table, "icm", "town01"), 50.0);
  EXPECT_DOUBLE_EQ(average_over_routes(table, "icm", "town02"), 25.0);
  const std::string md = render_markdown(report, "town01", "town02");
  EXPECT_NE(md.find("| icm | 50.0 | 25.0 | 25.0 |"), std::string::npos) << md;
  EXPECT_NE(md.find("| icm | 75.0 ["), std::string::npos) << md;
  EXPECT_NE(md.find("off_road"), std::string::npos);
  const std::string csv = render_csv(report);
  EXPECT_NE(csv.find("zero_shot,exploration,icm,town02,two_turn,1,4,0,0.000,100.000"),
            std::string::npos)
      << csv;
  EXPECT_NE(render_latex(report).find("\\multicolumn{2}{c}{two\\_turn}"), std::string::npos);
}

TEST(Report, RouteCompletionIsAveragedLikeTheSuccessRate) {
  std::vector<EpisodeRecord> records;
  // Seed 0: density 5 at 0.2 and 0.4 (mean 30%), density 20 at 1.0 (100%): 65% for the seed;
  // seed 1: 0.5 (50%). The cell: 57.5%, not the pooled mean of the four episodes (52.5%).
  add_episodes(records, "rnd", 0, "town01", "right_loop", 5, 2, 0, "off_route");
  records[records.size() - 2].route_completion = 0.2;
  records.back().route_completion = 0.4;
  add_episodes(records, "rnd", 0, "town01", "right_loop", 20, 1, 1);
  records.back().route_completion = 1.0;
  add_episodes(records, "rnd", 1, "town01", "right_loop", 5, 1, 0, "collision");
  records.back().route_completion = 0.5;
  const Report report = aggregate(records);
  const Table& table = report.tables.begin()->second;
  EXPECT_DOUBLE_EQ(table.cells.at("rnd").at("town01").at("right_loop").rc, 57.5);
  const std::string md = render_markdown(report, "town01", "town02");
  EXPECT_NE(md.find("| method | town | right_loop | average |"), std::string::npos) << md;
  EXPECT_NE(md.find("| rnd | town01 | 57.5 | 57.5 |"), std::string::npos) << md;
  EXPECT_NE(render_csv(report).find(",57.500\n"), std::string::npos) << render_csv(report);
}

TEST(Report, TheLayoutBoundRowCountsTheRoutesOneLayoutRuleFollows) {
  std::vector<EpisodeRecord> records;
  add_episodes(records, "disag", 0, "town01", "straight", 10, 4, 4);
  add_episodes(records, "disag", 0, "town01", "right_loop", 10, 4, 0, "off_route");
  add_episodes(records, "disag", 0, "town01", "left_loop", 10, 4, 0, "off_route");
  add_episodes(records, "disag", 0, "town02", "straight", 10, 4, 4);
  const Report report = aggregate(records);
  // straight clashes with right_loop at {r,s} and with left_loop at {l,s}; right_loop and
  // left_loop agree, so one rule follows two of the three routes on town01.
  TownChoices choices;
  choices["town01"] = {{"straight", "a", "rs", 's'},
                       {"straight", "b", "ls", 's'},
                       {"right_loop", "c", "rs", 'r'},
                       {"left_loop", "d", "ls", 'l'},
                       {"two_turn", "e", "lr", 'l'}};
  const std::string md = render_markdown(report, "town01", "town02", choices);
  // town01: 2 of the 3 routes the table holds (two_turn's choice is not counted); town02 has
  // no choices given: "-".
  EXPECT_NE(md.find("| *layout bound* | 66.7 | - | |"), std::string::npos) << md;
  // Without choices there is no such row.
  EXPECT_EQ(render_markdown(report, "town01", "town02").find("layout bound"), std::string::npos);
  // The built-in towns' own routes: two of four on each (straight and right_loop).
  const TownChoices builtin = route_choices_of(report);
  ASSERT_EQ(builtin.size(), 2u);
  std::vector<EpisodeRecord> all;
  for (const std::string town : {"town01", "town02"}) {
    for (const std::string route : {"straight", "right_loop", "left_loop", "two_turn"}) {
      add_episodes(all, "disag", 0, town, route, 10, 1, 0, "off_route");
    }
  }
  EXPECT_NE(render_markdown(aggregate(all), "town01", "town02", builtin)
                .find("| *layout bound* | 50.0 | 50.0 | |"),
            std::string::npos);
}

TEST(Report, TheLayoutBoundIsTakenFromTheRouteSetTheEvaluationsRanWith) {
  std::vector<EpisodeRecord> records;
  for (const std::string town : {"town01", "town02"}) {
    for (const std::string route : {"straight", "right_loop", "left_loop", "two_turn"}) {
      add_episodes(records, "disag", 0, town, route, 10, 1, 0, "off_route");
    }
  }
  const Report report = aggregate(records);
  const std::vector<std::string> routes = {"straight", "right_loop", "left_loop", "two_turn"};
  // The default set's rule follows straight and right_loop, the mirror set's straight and
  // left_loop: the choices come from the set asked for.
  for (const auto& [set, loop] : std::vector<std::pair<std::string, std::string>>{
           {"right", "right_loop"}, {"left", "left_loop"}}) {
    const TownChoices choices = route_choices_of(report, set);
    ASSERT_EQ(choices.size(), 2u) << set;
    for (const auto& [town, town_choices] : choices) {
      const auto bound = env::layout_rule_bound(routes, town_choices);
      EXPECT_EQ(bound.routes_followed, (std::vector<std::string>{"straight", loop}))
          << set << " " << town;
    }
    const std::string md = render_markdown(report, "town01", "town02", choices, set);
    EXPECT_NE(md.find("route set `" + set + "`"), std::string::npos) << md;
  }
  try {
    route_choices_of(report, "middle");
    ADD_FAILURE() << "an unknown route set was accepted";
  } catch (const std::invalid_argument& e) {
    // The message names every set the towns have, so the user knows what to give.
    EXPECT_NE(std::string(e.what()).find("one of right (the default), left"), std::string::npos)
        << e.what();
  }
}

TEST(Report, FailureColumnsFollowTheEventOrderOffRouteIncluded) {
  std::vector<EpisodeRecord> records;
  add_episodes(records, "icm", 0, "town01", "right_loop", 10, 3, 0, "off_route");
  add_episodes(records, "icm", 0, "town01", "left_loop", 10, 2, 0, "time_limit");
  add_episodes(records, "icm", 0, "town01", "straight", 10, 1, 0, "collision");
  const std::string md = render_markdown(aggregate(records), "town01", "town02");
  EXPECT_NE(md.find("| method | town | route | collision | time_limit | off_route |"),
            std::string::npos)
      << md;
  EXPECT_NE(md.find("| icm | town01 | right_loop | 0 | 0 | 3 |"), std::string::npos) << md;
}

TEST(Report, EmptyInputsAreClearErrors) {
  testing::TempDir dir;
  EXPECT_THROW(aggregate({}), std::invalid_argument);
  try {
    load_results({dir.path()});
    FAIL();
  } catch (const CsvError& error) {
    EXPECT_NE(std::string(error.what()).find("run an evaluation first"), std::string::npos);
  }
  try {
    load_results({dir.path() / "missing"});
    FAIL();
  } catch (const CsvError& error) {
    const std::string message = error.what();
    EXPECT_NE(message.find((dir.path() / "missing").string()), std::string::npos) << message;
    EXPECT_NE(message.find("does not exist; name a run directory"), std::string::npos) << message;
  }
}

// Training episodes (train-episodes.csv, eval_kind "training") are no evaluation: a report
// over a file that holds them leaves them out, and one with nothing else says where they go.
TEST(Report, TrainingEpisodesAreLeftOutOfTheTables) {
  testing::TempDir dir;
  std::vector<EpisodeRecord> records;
  add_episodes(records, "disag", 0, "town01", "straight", 10, 3, 2);
  EpisodeRecord training = records.front();
  training.eval_kind = "training";
  const auto file = dir.path() / "mixed.csv";
  {
    EpisodeCsvWriter writer(file);
    for (const auto& r : records) writer.write(r);
    writer.write(training);
  }
  EXPECT_EQ(load_results({file}).size(), 3u);
  const auto only = dir.path() / "train-episodes.csv";
  { EpisodeCsvWriter(only).write(training); }
  try {
    load_results({only});
    FAIL();
  } catch (const CsvError& error) {
    EXPECT_NE(std::string(error.what()).find("only 1 training episodes, which `indrive episodes`"),
              std::string::npos)
        << error.what();
  }
}

TEST(Report, LearningCurveFilesAreLeftOutOfTheTables) {
  testing::TempDir dir;
  std::filesystem::create_directories(dir.path() / "eval");
  std::vector<EpisodeRecord> records;
  add_episodes(records, "disag", 0, "town01", "straight", 10, 3, 2);
  {
    EpisodeCsvWriter writer(dir.path() / "eval" / "evaluator-0.csv");
    for (const auto& r : records) writer.write(r);
  }
  // A curve file with other columns: reading it as results would throw.
  std::ofstream(dir.path() / "eval" / "curve-0.csv") << "env_steps,policy_version\n100,1\n";
  const auto loaded = load_results({dir.path()});
  EXPECT_EQ(loaded.size(), 3u);
  // Only a curve file: nothing to report, and the error says so.
  std::filesystem::remove(dir.path() / "eval" / "evaluator-0.csv");
  EXPECT_THROW(load_results({dir.path()}), CsvError);
}

// A row's protocol reaches the report: the two protocols' results never share a table, each
// table names its protocol, the CSV carries it, the layout bound stands under strict tables
// only, and zero-shot tables of the CARLA towns show the paper's averages beside ours.
TEST(Report, EachProtocolGetsItsOwnTablesWithThePapersFiguresBeside) {
  std::vector<EpisodeRecord> records;
  add_episodes(records, "disag", 0, "carla_town01", "straight_1", 10, 4, 3, "out_of_lane",
               "indrive_code");
  add_episodes(records, "disag", 0, "carla_town02", "straight_1", 10, 4, 1, "out_of_lane",
               "indrive_code");
  add_episodes(records, "disag", 0, "carla_town01", "straight_1", 10, 4, 2, "off_route");
  add_episodes(records, "disag", 0, "carla_town02", "straight_1", 10, 4, 0, "off_route");
  const Report report = aggregate(records);
  ASSERT_EQ(report.tables.size(), 2u);
  EXPECT_DOUBLE_EQ(report.tables.at({"indrive_code", "zero_shot", "exploration"})
                       .cells.at("disag")
                       .at("carla_town01")
                       .at("straight_1")
                       .sr,
                   75.0);
  EXPECT_DOUBLE_EQ(report.tables.at({"strict", "zero_shot", "exploration"})
                       .cells.at("disag")
                       .at("carla_town01")
                       .at("straight_1")
                       .sr,
                   50.0);
  TownChoices choices;
  choices["carla_town01"] = {{"straight_1", "a", "rs", 's'}};
  choices["carla_town02"] = {{"straight_1", "b", "rs", 's'}};
  const std::string md = render_markdown(report, "town01", "town02", choices);
  EXPECT_NE(md.find("(protocol indrive_code: the public InDRiVE code's rules)"), std::string::npos)
      << md;
  EXPECT_NE(md.find("(protocol strict)"), std::string::npos) << md;
  // The gap falls back to the CARLA namesakes of town01 and town02; the paper's row beside.
  EXPECT_NE(md.find("gap (carla_town01 - carla_town02)"), std::string::npos) << md;
  EXPECT_NE(md.find("| disag | 75.0 | 25.0 | 50.0 |"), std::string::npos) << md;
  EXPECT_NE(md.find("| *paper, disag* | 75.65 | 73.20 | 2.45 |"), std::string::npos) << md;
  // One layout bound row: the strict table's.
  const auto first = md.find("*layout bound* |");
  ASSERT_NE(first, std::string::npos) << md;
  EXPECT_EQ(md.find("*layout bound* |", first + 1), std::string::npos) << md;
  EXPECT_GT(first, md.find("(protocol strict)")) << md;
  const std::string csv = render_csv(report);
  EXPECT_NE(csv.find("protocol,eval_kind,task,method,town,route"), std::string::npos) << csv;
  EXPECT_NE(csv.find("indrive_code,zero_shot,exploration,disag,carla_town01,straight_1,"),
            std::string::npos)
      << csv;
  EXPECT_EQ(paper_zero_shot_average("icm", "carla_town02"), 48.61);
  EXPECT_FALSE(paper_zero_shot_average("icm", "town02").has_value());
  EXPECT_FALSE(paper_zero_shot_average("random", "carla_town01").has_value());
}

TEST(Report, TheCarlaTownsRoutesSortByKind) {
  std::vector<EpisodeRecord> records;
  for (const std::string route : {"two_turn_1", "left_1", "straight_2", "right_1", "straight_1"}) {
    add_episodes(records, "disag", 0, "carla_town01", route, 10, 1, 1, "", "indrive_code");
  }
  add_episodes(records, "disag", 0, "carla_town02", "two_turn_2", 10, 1, 1, "", "indrive_code");
  const Report report = aggregate(records);
  EXPECT_EQ(report.tables.begin()->second.routes,
            (std::vector<std::string>{"straight_1", "straight_2", "right_1", "left_1", "two_turn_1",
                                      "two_turn_2"}));
  // Each town's table lists the routes evaluated there.
  const std::string md = render_markdown(report, "town01", "town02");
  const auto town01 = md.find("### carla_town01"), town02 = md.find("### carla_town02");
  ASSERT_NE(town01, std::string::npos);
  ASSERT_NE(town02, std::string::npos);
  const std::string first = md.substr(town01, town02 - town01);
  EXPECT_NE(first.find("two_turn_1 SR"), std::string::npos) << first;
  EXPECT_EQ(first.find("two_turn_2 SR"), std::string::npos) << first;
  const std::string second = md.substr(town02, md.find("###", town02 + 3) - town02);
  EXPECT_EQ(second,
            "### carla_town02\n\n| method | two_turn_2 SR | FR | n |\n|---|---|---|---|\n"
            "| disag | 100.0 [20.7, 100.0] | 0.0 | 1 |\n\n");
}

}  // namespace
}  // namespace indrive::deploy
