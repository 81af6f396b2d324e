// The route probe: where each route chooses (choice points of the built-in towns), the linear
// probe on data whose answer is known, the scoring against the layout rule, and a short
// collection run with an untrained tiny snapshot.
#include "indrive/route_probe/route_probe.h"

#include <gtest/gtest.h>

#include <atomic>
#include <random>
#include <set>

#include "child_process.h"
#include "indrive/actor/snapshot_file.h"
#include "indrive/agent/agent.h"
#include "indrive/envserver/town.h"
#include "testing.h"

namespace indrive::route_probe {
namespace {

using agent::write_snapshot_file;

using namespace std::chrono_literals;

TEST(ChoicePoints, EachChoiceOfABuiltInRouteHasItsJunctionOnTheRoute) {
  for (const std::string name : {"town01", "town02"}) {
    const env::Town town = env::load_town(name);
    for (const env::Route& route : town.routes) {
      const auto choices = env::route_choices(town.net, {route.spec()});
      const auto points = choice_points(town.net, route);
      ASSERT_EQ(points.size(), choices.size()) << name << " " << route.name();
      std::multiset<std::string> from_choices, from_points;
      for (const auto& c : choices) from_choices.insert(c.approach + c.layout + c.taken);
      for (const auto& p : points) from_points.insert(p.approach + p.layout + p.taken);
      EXPECT_EQ(from_points, from_choices) << name << " " << route.name();
      for (size_t i = 0; i < points.size(); ++i) {
        EXPECT_GT(points[i].junction_s_m, 0.0) << name << " " << route.name();
        EXPECT_LE(points[i].junction_s_m, route.length_m()) << name << " " << route.name();
        if (i > 0) {
          EXPECT_GT(points[i].junction_s_m, points[i - 1].junction_s_m);
        }
      }
      if (route.name() == "straight") {
        // One T-junction crossed straight on; the route ends before the next.
        ASSERT_EQ(points.size(), 1u) << name;
        EXPECT_EQ(points[0].taken, 's');
        EXPECT_LT(points[0].junction_s_m, route.length_m() - 5.0) << name;
      }
    }
  }
}

// Samples whose features are x = onehot(label) * signal + noise (dims 12).
struct Synthetic {
  std::vector<std::vector<float>> x;
  std::vector<int> labels, groups;
};
Synthetic synthetic(int n, double signal, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<float> noise(0.0f, 1.0f);
  Synthetic out;
  for (int i = 0; i < n; ++i) {
    const int label = i % 3;
    std::vector<float> row(12);
    for (auto& v : row) v = noise(rng);
    row[label] += static_cast<float>(signal);
    out.x.push_back(row);
    out.labels.push_back(label);
    out.groups.push_back(i / 10);
  }
  return out;
}
double accuracy(const LinearProbe& probe, const Synthetic& data) {
  int right = 0;
  for (size_t i = 0; i < data.x.size(); ++i) right += probe.predict(data.x[i]) == data.labels[i];
  return static_cast<double>(right) / data.x.size();
}

TEST(LinearProbe, ReadsAnInformativeFeatureAndNotNoise) {
  const LinearProbe informed = LinearProbe::fit(
      synthetic(300, 4.0, 1).x, synthetic(300, 4.0, 1).labels, 3, synthetic(300, 4.0, 1).groups);
  EXPECT_GT(accuracy(informed, synthetic(300, 4.0, 2)), 0.95);
  const Synthetic noise = synthetic(300, 0.0, 3);
  const LinearProbe blind = LinearProbe::fit(noise.x, noise.labels, 3, noise.groups);
  // Three balanced classes: chance is a third; 300 fresh samples stay well under a half.
  EXPECT_LT(accuracy(blind, synthetic(300, 0.0, 4)), 0.5);
  // Cross-validation chose some lambda of the list.
  EXPECT_NE(std::find(std::begin(kProbeLambdas), std::end(kProbeLambdas), blind.lambda()),
            std::end(kProbeLambdas));
  EXPECT_THROW(LinearProbe::fit({}, {}, 3, {}), std::invalid_argument);
  EXPECT_THROW(LinearProbe::fit({{1.0f}, {1.0f, 2.0f}}, {0, 1}, 3, {0, 1}), std::invalid_argument);
  EXPECT_THROW(LinearProbe::fit({{1.0f}, {2.0f}}, {0, 3}, 3, {0, 1}), std::invalid_argument);
}

// Two routes on a town with one layout ("lr"): route "a" turns left, "b" right. `view` tells
// the exit, `memory` is noise.
std::vector<ProbeSample> two_route_samples(const std::string& town, int episodes,
                                           std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<float> noise(0.0f, 1.0f);
  std::vector<ProbeSample> samples;
  for (const char* route : {"a", "b"}) {
    for (int episode = 0; episode < episodes; ++episode) {
      for (int decision = 0; decision < 2; ++decision) {
        for (int step = 0; step < 6; ++step) {
          ProbeSample s;
          s.town = town;
          s.route = route;
          s.density = 5;
          s.episode = episode;
          s.decision = decision;
          s.layout = "lr";
          s.taken = route[0] == 'a' ? 'l' : 'r';
          s.view = {s.taken == 'l' ? 3.0f : -3.0f, noise(rng)};
          s.memory = {noise(rng), noise(rng), noise(rng)};
          s.latent = {noise(rng)};
          samples.push_back(s);
        }
      }
    }
  }
  return samples;
}

TEST(RouteProbeScore, TheLayoutRuleFollowsOneRouteAndAnInformativeViewBoth) {
  auto samples = two_route_samples("t1", 6, 5);
  const auto other = two_route_samples("t2", 2, 6);
  samples.insert(samples.end(), other.begin(), other.end());
  const ProbeReport report = score_route_probe(samples, "t1", "t2");
  ASSERT_EQ(report.evaluations.size(), 2u);
  for (const ProbeEvaluation& e : report.evaluations) {
    ASSERT_EQ(e.scores.size(), 1u + kProbeFeatures);
    const ProbeScore& layout = e.scores[0];
    EXPECT_EQ(layout.features, "layout");
    // One layout, two exits: the rule takes one, so one route of two is followed.
    EXPECT_DOUBLE_EQ(layout.step_accuracy, 0.5) << e.name;
    EXPECT_DOUBLE_EQ(layout.mean_route_followed, 0.5) << e.name;
    const ProbeScore& view = e.scores[1 + static_cast<int>(ProbeFeature::kView)];
    EXPECT_EQ(view.features, "view");
    EXPECT_DOUBLE_EQ(view.decision_accuracy, 1.0) << e.name;
    EXPECT_DOUBLE_EQ(view.route_followed.at("a"), 1.0) << e.name;
    EXPECT_DOUBLE_EQ(view.route_followed.at("b"), 1.0) << e.name;
    const ProbeScore& memory = e.scores[1 + static_cast<int>(ProbeFeature::kMemory)];
    EXPECT_LT(memory.mean_route_followed, 0.75) << e.name;
  }
  // In-town: even episodes train, odd ones test (3 x 2 routes x 2 decisions), at 4 places.
  EXPECT_EQ(report.evaluations[0].scores[0].decisions, 12);
  EXPECT_EQ(report.evaluations[0].scores[0].places, 4);
  EXPECT_EQ(report.evaluations[0].scores[0].places_right, 2);  // route a's two
  EXPECT_EQ(report.evaluations[0].scores[1 + static_cast<int>(ProbeFeature::kView)].places_right,
            4);
  EXPECT_EQ(report.evaluations[1].scores[0].decisions, 8);
  // A town with one episode per cell cannot be split.
  EXPECT_THROW(score_route_probe(two_route_samples("t1", 1, 7), "t1", ""), std::invalid_argument);
  testing::TempDir dir;
  const std::string text = write_probe_report(report, dir.path() / "probe", "synthetic");
  EXPECT_NE(text.find("| layout | 50.0% |"), std::string::npos) << text;
  EXPECT_TRUE(std::filesystem::exists(dir.path() / "probe" / "probe.md"));
}

TEST(RouteProbe, CollectsStatesBeforeEachChoiceOfTheOraclesEpisodes) {
  testing::TempDir dir;
  agent::AgentConfig agent_config = agent::preset("tiny");
  agent::Agent agent(agent_config);
  const auto file = dir.path() / "snapshot.params";
  write_snapshot_file(file, agent.snapshot(), agent_config);
  const auto config = service::ServiceConfig::resolve(
      {.run_dir = dir.path() / "probe-run",
       .overrides = {"eval.snapshot_file=" + file.string(), "eval.kind=zero_shot",
                     "eval.towns=town01", "eval.routes=straight,right_loop", "eval.densities=[5]",
                     "eval.episodes_per_cell=1"}});
  RouteProbe probe(config);
  const std::atomic<bool> stop{false};
  const std::vector<ProbeSample> samples = probe.collect(stop);
  ASSERT_FALSE(samples.empty());
  const env::Town town = env::load_town("town01");
  std::set<std::pair<std::string, int>> decisions;
  for (const ProbeSample& s : samples) {
    EXPECT_EQ(s.town, "town01");
    EXPECT_GE(s.to_junction_m, config.config().get<double>("eval.probe_near_m"));
    EXPECT_LE(s.to_junction_m, config.config().get<double>("eval.probe_far_m"));
    EXPECT_EQ(s.memory.size(), static_cast<size_t>(agent_config.world_model.deter));
    EXPECT_EQ(s.latent.size(), static_cast<size_t>(agent_config.world_model.stoch_dim()));
    EXPECT_FALSE(s.view.empty());
    EXPECT_GE(s.previous_action, 0);
    EXPECT_LT(s.previous_action, agent::kNumActions);
    decisions.emplace(s.route, s.decision);
    // Its label is the route's exit at that choice point.
    const auto points = choice_points(town.net, env::find_route(town.routes, s.route));
    EXPECT_EQ(s.taken, points.at(s.decision).taken);
    EXPECT_EQ(s.approach, points.at(s.decision).approach);
  }
  // The oracle drives both routes through every choice (density 5, one episode each).
  const auto straight = choice_points(town.net, env::find_route(town.routes, "straight"));
  const auto right = choice_points(town.net, env::find_route(town.routes, "right_loop"));
  EXPECT_EQ(decisions.size(), straight.size() + right.size());
}

// As a user runs it: indrive-route-probe --snapshot FILE writes <run>/probe/probe.md with the
// held-out episodes of the training town and the other town; without a file it says what to add.
TEST(RouteProbe, TheCommandWritesBothTablesAndRefusesAMissingSnapshot) {
  testing::TempDir dir;
  const agent::AgentConfig tiny = agent::preset("tiny");
  const auto file = dir.path() / "untrained.params";
  write_snapshot_file(file, agent::Agent(tiny).snapshot(), tiny);
  const std::string program = std::string(INDRIVE_BIN_DIR) + "/indrive-route-probe";
  const auto log = dir.path() / "probe.log";
  testing::Child probe(
      {program, "--snapshot", file.string(), "--run-dir", (dir.path() / "run").string(), "--set",
       "eval.kind=zero_shot", "--set", "eval.routes=straight,right_loop", "--set",
       "eval.densities=[5]", "--set", "eval.episodes_per_cell=2"},
      log);
  ASSERT_EQ(probe.wait(120s), 0) << testing::slurp(log);
  const std::string text = testing::slurp(dir.path() / "run" / "probe" / "probe.md");
  EXPECT_NE(text.find("## town01, held-out episodes"), std::string::npos) << text;
  EXPECT_NE(text.find("test town02"), std::string::npos) << text;
  for (const char* row : {"| layout |", "| action |", "| view |", "| memory |", "| actor |"}) {
    EXPECT_NE(text.find(row), std::string::npos) << row << "\n" << text;
  }
  EXPECT_NE(testing::slurp(log).find("episode 8/8"), std::string::npos) << testing::slurp(log);

  const auto bad_log = dir.path() / "bad.log";
  testing::Child bad({program, "--run-dir", (dir.path() / "bad").string()}, bad_log);
  EXPECT_NE(bad.wait(60s), 0);
  EXPECT_NE(testing::slurp(bad_log).find("--snapshot is required"), std::string::npos)
      << testing::slurp(bad_log);
  // A training town outside the grid is refused before any episode is driven.
  const auto town_log = dir.path() / "town.log";
  testing::Child town(
      {program, "--snapshot", file.string(), "--run-dir", (dir.path() / "town").string(), "--set",
       "eval.towns=town01", "--train-town", "town02"},
      town_log);
  EXPECT_NE(town.wait(60s), 0);
  EXPECT_NE(testing::slurp(town_log).find("--train-town town02 is not among"), std::string::npos)
      << testing::slurp(town_log);
  EXPECT_EQ(testing::slurp(town_log).find("episode 1/"), std::string::npos);
}

}  // namespace
}  // namespace indrive::route_probe
