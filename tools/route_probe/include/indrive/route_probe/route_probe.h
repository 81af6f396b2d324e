// The route probe: does what a snapshot's policy sees tell which exit its route takes at a
// junction? A policy that sees no route picks its exit from what it sees and remembers; on the
// built-in towns a policy that goes by a junction's layout alone follows at most one route in
// four (envserver/routes.h, layout_rule_bound). The probe measures whether the snapshot's
// state carries more than the layout: the oracle drives every route of the protocol grid, the
// snapshot's world model filters its frames and actions as it would when acting, and at each
// junction approach that is a choice (two or more exits) the state of the last steps before the
// junction is recorded with the exit the route takes. Linear probes (ridge classifiers, one per
// feature set) are fitted on some episodes and scored on others:
//   view     e_t, the encoder's embedding of the current frame alone
//   memory   h_t, the RSSM's deterministic state (all earlier frames and actions)
//   latent   s_t, the posterior's stochastic state (h_t and the frame)
//   actor    [h_t; s_t], what the actor acts on
//   layout   the junction's layout alone: the layout -> exit rule that follows the most routes
//            of the training episodes (the layout bound's rule, envserver/routes.h)
//   action   the oracle's previous action alone (one-hot): a leak check. The oracle steers
//            towards a point up to 8 m ahead, so close to a junction its actions, and through
//            them the state, already show the turn; the window of recorded states ends
//            eval.probe_near_m before the junction so that this probe stays at the layout's
//            level, and a feature set is only credited with what exceeds it.
// A feature set that identifies the exit well above the layout rule could drive more routes than
// the layout bound allows; one at the layout rule's level cannot. Scored twice: on held-out
// episodes of the training town (same junctions, other traffic and spawns), and on another
// town (whose routes a policy trained on the first never saw).
//
//   RouteProbe probe(config);                 // eval.snapshot_file, eval.towns, ...
//   auto samples = probe.collect(stop);       // oracle episodes, states at the approaches
//   ProbeReport report = score_route_probe(samples, "town01", "town02");
//   write_probe_report(report, run_dir / "probe", "title");
#pragma once

#include <atomic>
#include <filesystem>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "indrive/envserver/net.h"
#include "indrive/envserver/routes.h"
#include "indrive/service/run_config.h"

namespace indrive::route_probe {

// A junction where a route chooses: the route reaches it at arc length junction_s_m (where the
// first lane inside the junction begins) from `approach`, the junction offers `layout` and the
// route takes `taken` ('l', 'r', 's').
struct ChoicePoint {
  std::string approach;
  std::string layout;
  char taken = 's';
  double junction_s_m = 0.0;
};
// The choice points of `route` (built from `net`), in driving order: the junctions of
// route_choices() with where the route enters them.
std::vector<ChoicePoint> choice_points(const env::RoadNetwork& net, const env::Route& route);

// The feature sets the probe compares, in report order.
enum class ProbeFeature { kAction, kView, kMemory, kLatent, kActor };
inline constexpr int kProbeFeatures = 5;
const char* to_string(ProbeFeature feature);

// One step before a choice point.
struct ProbeSample {
  std::string town, route;
  int density = 0;
  int episode = 0;   // the cell's episode index
  int decision = 0;  // which choice point of the route (index into choice_points)
  std::string approach, layout;
  char taken = 's';
  double to_junction_m = 0.0;  // distance along the route to the junction
  int previous_action = 0;     // the oracle's action of the step before (0 on the first)
  std::vector<float> view, memory, latent;
  // The values of one feature set (kActor: memory then latent; kAction: 9 values, one-hot).
  std::vector<float> features(ProbeFeature feature) const;
};

// A linear probe: standardised features, one ridge regression per class onto a one-hot target,
// the class with the largest output predicted. lambda is chosen on the training samples alone
// by leave-groups-out cross-validation over kProbeLambdas (groups: episodes), the same rule for
// every feature set.
inline constexpr double kProbeLambdas[] = {0.1, 1.0, 10.0, 100.0, 1000.0, 10000.0};
class LinearProbe {
 public:
  // x: one row per sample; labels in [0, classes); groups: the cross-validation groups (at least
  // two distinct values, else lambda is the middle of the list). Throws std::invalid_argument
  // for empty or ragged input.
  static LinearProbe fit(const std::vector<std::vector<float>>& x, const std::vector<int>& labels,
                         int classes, const std::vector<int>& groups);
  int predict(const std::vector<float>& x) const;
  double lambda() const { return lambda_; }

 private:
  std::vector<double> mean_, scale_;
  std::vector<std::vector<double>> weights_;  // (classes, dims + 1), bias last
  double lambda_ = 0.0;
};

// How well one feature set tells the exit.
struct ProbeScore {
  std::string features;  // to_string(ProbeFeature) or "layout"
  double lambda = 0.0;   // chosen ridge weight (0 for layout)
  int samples = 0;       // test steps
  double step_accuracy = 0.0;
  int decisions = 0;               // test (episode, choice point) pairs
  double decision_accuracy = 0.0;  // a decision counts when most of its steps are right
  // Distinct (route, choice point) pairs of the test episodes, and those most of whose
  // decisions are right: decisions of one place in several episodes are far from independent,
  // so this is the sample size that counts.
  int places = 0, places_right = 0;
  // Per route: the share of test episodes whose every decision was right; and their average
  // over routes, what a policy taking its exits this way could complete at most (if it drove
  // perfectly otherwise).
  std::map<std::string, double> route_followed;
  double mean_route_followed = 0.0;
};
struct ProbeEvaluation {
  std::string name;  // e.g. "town01, held-out episodes"
  std::string train, test;
  int train_samples = 0, test_samples = 0;
  std::vector<ProbeScore> scores;  // layout first, then the feature sets
  // The layout rule: layout_rule_bound()'s over the training decisions; layouts it leaves free
  // take the exit most training decisions take.
  std::map<std::string, char> layout_rule;
};
struct ProbeReport {
  std::vector<ProbeEvaluation> evaluations;
};

// Scores the probe: within `train_town` (its even episodes train, odd ones test) and, when
// `other_town` is non-empty and has samples, trained on every sample of train_town and tested on
// other_town's. Throws std::invalid_argument when train_town has no samples or fewer than two
// episodes.
ProbeReport score_route_probe(const std::vector<ProbeSample>& samples,
                              const std::string& train_town, const std::string& other_town);

// Writes probe.md (a table per evaluation, a line per score) into `dir`, creating it; returns
// its text. `settings`: a line saying how the samples were collected (probe_settings()).
std::string write_probe_report(const ProbeReport& report, const std::filesystem::path& dir,
                               const std::string& title, const std::string& settings = "");
// The collection settings of a configuration, as one line for the report.
std::string probe_settings(const config::Config& config);

// Drives the probe's episodes: the config's protocol grid (eval.towns, eval.routes,
// eval.densities, eval.episodes_per_cell) with the oracle (eval.oracle_speed_mps; it coasts
// only with eval.probe_oracle_brake, off by default: its coasting for crossing traffic depends
// on the turn ahead, and with it on the action row followed town02's right_loop in 83% of the
// episodes of a 2026-12-04 run, where the layout rule follows none), the snapshot file
// eval.snapshot_file filtering, eval.head's actor not acting.
// Records the states from eval.probe_far_m to eval.probe_near_m before each choice point.
class RouteProbe {
 public:
  // Throws EvalError when no snapshot file is given or it does not fit, and the env's errors.
  explicit RouteProbe(const service::ServiceConfig& config);
  ~RouteProbe();
  RouteProbe(const RouteProbe&) = delete;
  RouteProbe& operator=(const RouteProbe&) = delete;
  // Runs every episode of the grid (logs progress); stops early when `stop` is set.
  std::vector<ProbeSample> collect(const std::atomic<bool>& stop);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace indrive::route_probe
