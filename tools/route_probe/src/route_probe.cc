#include "indrive/route_probe/route_probe.h"

#include <Eigen/Dense>
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <fstream>
#include <numeric>
#include <set>
#include <sstream>
#include <stdexcept>
#include <tuple>

#include "indrive/actor/actor_config.h"
#include "indrive/actor/env_adapter.h"
#include "indrive/actor/eval_protocol_record.h"
#include "indrive/actor/evaluator.h"
#include "indrive/actor/policies.h"
#include "indrive/actor/snapshot_file.h"
#include "indrive/agent/policy.h"
#include "indrive/basics/check.h"
#include "indrive/basics/log.h"
#include "indrive/envserver/env.h"

namespace indrive::route_probe {

// The actor's evaluation pieces the probe drives with.
using actor::acting_config;
using actor::adopt_snapshot_architecture;
using actor::check_snapshot_head;
using actor::EpisodePolicy;
using actor::EpisodeSpec;
using actor::eval_config;
using actor::EvalConfig;
using actor::EvalError;
using actor::make_oracle_policy;
using actor::PolicyHead;
using actor::protocol_env_config;
using actor::protocol_grid;
using actor::ProtocolGrid;
using actor::resolve_head;
using actor::route_step_budget;
using actor::snapshot_file_path;

namespace {

int exit_class(char taken) { return taken == 'l' ? 0 : taken == 'r' ? 1 : 2; }
char exit_code(int label) { return "lrs"[label]; }

std::string fixed(double value, int digits) {
  char text[32];
  std::snprintf(text, sizeof text, "%.*f", digits, value);
  return text;
}

// An episode of the grid, the unit of the train/test split and of cross-validation.
using EpisodeKey = std::tuple<std::string, std::string, int, int>;  // town, route, density, ep
EpisodeKey episode_key(const ProbeSample& s) { return {s.town, s.route, s.density, s.episode}; }

}  // namespace

std::vector<ChoicePoint> choice_points(const env::RoadNetwork& net, const env::Route& route) {
  const std::vector<env::RouteChoice> choices = env::route_choices(net, {route.spec()});
  // Where the route enters each junction: the first waypoint on an internal lane after one on
  // a normal lane, whose edge is the approach.
  std::vector<std::pair<std::string, double>> entries;
  const auto& waypoints = route.waypoints();
  for (size_t i = 1; i < waypoints.size(); ++i) {
    const int before = waypoints[i - 1].lane, now = waypoints[i].lane;
    if (before < 0 || now < 0) continue;
    if (!net.lanes()[before].internal && net.lanes()[now].internal) {
      entries.emplace_back(net.edges()[net.lanes()[before].edge].id, waypoints[i].s_m);
    }
  }
  std::vector<ChoicePoint> points;
  std::vector<bool> used(entries.size(), false);
  for (const env::RouteChoice& choice : choices) {
    ChoicePoint point{choice.approach, choice.layout, choice.taken, route.length_m()};
    // A loop's closing junction lies past its last waypoint: it stays at the end of the lap.
    for (size_t e = 0; e < entries.size(); ++e) {
      if (!used[e] && entries[e].first == choice.approach) {
        used[e] = true;
        point.junction_s_m = entries[e].second;
        break;
      }
    }
    points.push_back(point);
  }
  std::sort(points.begin(), points.end(), [](const ChoicePoint& a, const ChoicePoint& b) {
    return a.junction_s_m < b.junction_s_m;
  });
  return points;
}

const char* to_string(ProbeFeature feature) {
  switch (feature) {
    case ProbeFeature::kAction:
      return "action";
    case ProbeFeature::kView:
      return "view";
    case ProbeFeature::kMemory:
      return "memory";
    case ProbeFeature::kLatent:
      return "latent";
    case ProbeFeature::kActor:
      return "actor";
  }
  return "?";
}

std::vector<float> ProbeSample::features(ProbeFeature feature) const {
  switch (feature) {
    case ProbeFeature::kAction: {
      std::vector<float> one_hot(agent::kNumActions, 0.0f);
      one_hot.at(previous_action) = 1.0f;
      return one_hot;
    }
    case ProbeFeature::kView:
      return view;
    case ProbeFeature::kMemory:
      return memory;
    case ProbeFeature::kLatent:
      return latent;
    case ProbeFeature::kActor: {
      std::vector<float> both = memory;
      both.insert(both.end(), latent.begin(), latent.end());
      return both;
    }
  }
  return {};
}

// ---------------------------------------------------------------------------------------------
// The linear probe.

namespace {

// Ridge solutions for several lambdas from one eigendecomposition of the Gram matrix.
struct RidgeSolver {
  Eigen::MatrixXd vectors;    // eigenvectors of X^T X
  Eigen::VectorXd values;     // its eigenvalues
  Eigen::MatrixXd projected;  // V^T X^T Y
  RidgeSolver(const Eigen::MatrixXd& x, const Eigen::MatrixXd& y) {
    Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(x.transpose() * x);
    vectors = eig.eigenvectors();
    values = eig.eigenvalues().cwiseMax(0.0);
    projected = vectors.transpose() * (x.transpose() * y);
  }
  Eigen::MatrixXd weights(double lambda) const {
    Eigen::MatrixXd scaled = projected;
    for (Eigen::Index i = 0; i < scaled.rows(); ++i) scaled.row(i) /= values(i) + lambda;
    return vectors * scaled;  // (dims, classes)
  }
};

struct Standardised {
  Eigen::MatrixXd x;  // (n, d), centred and scaled
  Eigen::RowVectorXd mean, scale;
};
Standardised standardise(const std::vector<std::vector<float>>& rows,
                         const std::vector<size_t>& take) {
  const Eigen::Index n = static_cast<Eigen::Index>(take.size());
  const Eigen::Index d = static_cast<Eigen::Index>(rows[take.front()].size());
  std::vector<double> mean(static_cast<size_t>(d), 0.0), square(static_cast<size_t>(d), 0.0);
  for (size_t i : take)
    for (Eigen::Index j = 0; j < d; ++j) mean[j] += rows[i][j];
  for (auto& m : mean) m /= static_cast<double>(n);
  for (size_t i : take)
    for (Eigen::Index j = 0; j < d; ++j)
      square[j] += (rows[i][j] - mean[j]) * (rows[i][j] - mean[j]);
  Standardised out;
  out.mean.resize(d);
  out.scale.resize(d);
  for (Eigen::Index j = 0; j < d; ++j) {
    const double scale = std::sqrt(square[j] / static_cast<double>(n));
    out.mean(j) = mean[j];
    out.scale(j) = scale < 1e-8 ? 1.0 : scale;  // a constant feature: stays zero
  }
  out.x.resize(n, d);
  for (Eigen::Index i = 0; i < n; ++i)
    for (Eigen::Index j = 0; j < d; ++j)
      out.x(i, j) = (rows[take[i]][j] - out.mean(j)) / out.scale(j);
  return out;
}
Eigen::MatrixXd one_hot(const std::vector<int>& labels, const std::vector<size_t>& take,
                        int classes) {
  Eigen::MatrixXd y = Eigen::MatrixXd::Zero(static_cast<Eigen::Index>(take.size()), classes);
  for (size_t i = 0; i < take.size(); ++i) y(static_cast<Eigen::Index>(i), labels[take[i]]) = 1.0;
  return y;
}

}  // namespace

LinearProbe LinearProbe::fit(const std::vector<std::vector<float>>& x,
                             const std::vector<int>& labels, int classes,
                             const std::vector<int>& groups) {
  if (x.empty() || x.size() != labels.size() || x.size() != groups.size() || classes < 2) {
    throw std::invalid_argument("LinearProbe::fit: needs samples, one label and group each");
  }
  for (const auto& row : x) {
    if (row.size() != x.front().size() || row.empty())
      throw std::invalid_argument("LinearProbe::fit: rows of different lengths");
  }
  for (int label : labels) {
    if (label < 0 || label >= classes)
      throw std::invalid_argument("LinearProbe::fit: a label outside [0, classes)");
  }
  // Lambda by cross-validation over groups: up to 5 folds, groups dealt round-robin in order.
  std::vector<int> distinct(groups.begin(), groups.end());
  std::sort(distinct.begin(), distinct.end());
  distinct.erase(std::unique(distinct.begin(), distinct.end()), distinct.end());
  const int folds = std::min<int>(5, static_cast<int>(distinct.size()));
  constexpr int kLambdas = static_cast<int>(std::size(kProbeLambdas));
  LinearProbe probe;
  probe.lambda_ = kProbeLambdas[kLambdas / 2];
  if (folds >= 2) {
    std::vector<int> correct(kLambdas, 0);
    for (int fold = 0; fold < folds; ++fold) {
      std::vector<size_t> train, test;
      for (size_t i = 0; i < x.size(); ++i) {
        const auto at = std::lower_bound(distinct.begin(), distinct.end(), groups[i]);
        ((at - distinct.begin()) % folds == fold ? test : train).push_back(i);
      }
      if (train.empty() || test.empty()) continue;
      const Standardised s = standardise(x, train);
      const Eigen::MatrixXd y = one_hot(labels, train, classes);
      const Eigen::RowVectorXd y_mean = y.colwise().mean();
      const RidgeSolver solver(s.x, y.rowwise() - y_mean);
      Eigen::MatrixXd xt(static_cast<Eigen::Index>(test.size()), s.x.cols());
      for (size_t i = 0; i < test.size(); ++i)
        for (Eigen::Index j = 0; j < s.x.cols(); ++j)
          xt(static_cast<Eigen::Index>(i), j) = (x[test[i]][j] - s.mean(j)) / s.scale(j);
      for (int l = 0; l < kLambdas; ++l) {
        const Eigen::MatrixXd out = (xt * solver.weights(kProbeLambdas[l])).rowwise() + y_mean;
        for (size_t i = 0; i < test.size(); ++i) {
          Eigen::Index best = 0;
          out.row(static_cast<Eigen::Index>(i)).maxCoeff(&best);
          correct[l] += best == labels[test[i]];
        }
      }
    }
    // The most accurate; ties go to the larger lambda (the simpler probe).
    int best = 0;
    for (int l = 1; l < kLambdas; ++l)
      if (correct[l] >= correct[best]) best = l;
    probe.lambda_ = kProbeLambdas[best];
  }
  std::vector<size_t> all(x.size());
  std::iota(all.begin(), all.end(), size_t{0});
  const Standardised s = standardise(x, all);
  const Eigen::MatrixXd y = one_hot(labels, all, classes);
  const Eigen::RowVectorXd y_mean = y.colwise().mean();
  const Eigen::MatrixXd w = RidgeSolver(s.x, y.rowwise() - y_mean).weights(probe.lambda_);
  probe.mean_.assign(s.mean.data(), s.mean.data() + s.mean.size());
  probe.scale_.assign(s.scale.data(), s.scale.data() + s.scale.size());
  probe.weights_.assign(classes, std::vector<double>(w.rows() + 1));
  for (int c = 0; c < classes; ++c) {
    for (Eigen::Index j = 0; j < w.rows(); ++j) probe.weights_[c][j] = w(j, c);
    probe.weights_[c].back() = y_mean(c);
  }
  return probe;
}

int LinearProbe::predict(const std::vector<float>& x) const {
  INDRIVE_CHECK_EQ(x.size(), mean_.size());
  int best = 0;
  double best_value = -1e300;
  for (size_t c = 0; c < weights_.size(); ++c) {
    double value = weights_[c].back();
    for (size_t j = 0; j < x.size(); ++j) value += weights_[c][j] * (x[j] - mean_[j]) / scale_[j];
    if (value > best_value) best_value = value, best = static_cast<int>(c);
  }
  return best;
}

// ---------------------------------------------------------------------------------------------
// Scoring.

namespace {

// Scores step predictions of the test samples (one per sample, an exit code).
ProbeScore score_predictions(const std::string& name, double lambda,
                             const std::vector<const ProbeSample*>& test,
                             const std::vector<char>& predicted) {
  ProbeScore score;
  score.features = name;
  score.lambda = lambda;
  score.samples = static_cast<int>(test.size());
  int right = 0;
  // Per decision (episode, choice point): steps right, steps.
  std::map<std::pair<EpisodeKey, int>, std::pair<int, int>> decisions;
  for (size_t i = 0; i < test.size(); ++i) {
    const bool ok = predicted[i] == test[i]->taken;
    right += ok;
    auto& d = decisions[{episode_key(*test[i]), test[i]->decision}];
    d.first += ok;
    d.second += 1;
  }
  score.step_accuracy = test.empty() ? 0.0 : static_cast<double>(right) / test.size();
  // Per episode: every decision right.
  std::map<EpisodeKey, bool> followed;
  int decisions_right = 0;
  for (const auto& [key, counts] : decisions) {
    const bool ok = 2 * counts.first > counts.second;
    decisions_right += ok;
    auto [it, inserted] = followed.emplace(key.first, ok);
    if (!inserted) it->second = it->second && ok;
  }
  std::map<std::pair<std::string, int>, std::pair<int, int>> places;  // right, decisions
  for (const auto& [key, counts] : decisions) {
    auto& place = places[{std::get<1>(key.first), key.second}];
    place.first += 2 * counts.first > counts.second;
    place.second += 1;
  }
  score.places = static_cast<int>(places.size());
  for (const auto& [place, counts] : places) score.places_right += 2 * counts.first > counts.second;
  score.decisions = static_cast<int>(decisions.size());
  score.decision_accuracy =
      decisions.empty() ? 0.0 : static_cast<double>(decisions_right) / decisions.size();
  std::map<std::string, std::pair<int, int>> per_route;  // followed, episodes
  for (const auto& [key, ok] : followed) {
    auto& r = per_route[std::get<1>(key)];
    r.first += ok;
    r.second += 1;
  }
  for (const auto& [route, counts] : per_route) {
    score.route_followed[route] = static_cast<double>(counts.first) / counts.second;
    score.mean_route_followed += score.route_followed[route];
  }
  if (!per_route.empty()) score.mean_route_followed /= static_cast<double>(per_route.size());
  return score;
}

ProbeEvaluation evaluate(const std::string& name, const std::string& train_name,
                         const std::string& test_name, const std::vector<const ProbeSample*>& train,
                         const std::vector<const ProbeSample*>& test) {
  ProbeEvaluation out;
  out.name = name;
  out.train = train_name;
  out.test = test_name;
  out.train_samples = static_cast<int>(train.size());
  out.test_samples = static_cast<int>(test.size());
  // The layout rule: the one of the layout bound (env::layout_rule_bound over the training
  // decisions), which follows the most routes; layouts it leaves free take the exit most
  // training decisions take (ties: l, r, s order).
  std::map<std::string, std::array<int, 3>> votes;
  std::set<std::pair<EpisodeKey, int>> counted;
  std::vector<env::RouteChoice> choices;
  std::set<std::string> routes;
  for (const ProbeSample* s : train) {
    routes.insert(s->route);
    if (!counted.emplace(episode_key(*s), s->decision).second) continue;
    votes[s->layout][exit_class(s->taken)] += 1;
    choices.push_back({s->route, s->approach, s->layout, s->taken});
  }
  for (const auto& [layout, count] : votes) {
    out.layout_rule[layout] =
        exit_code(static_cast<int>(std::max_element(count.begin(), count.end()) - count.begin()));
  }
  const env::LayoutRuleBound bound =
      env::layout_rule_bound(std::vector<std::string>(routes.begin(), routes.end()), choices);
  for (const auto& [layout, exit] : bound.rule) out.layout_rule[layout] = exit;
  std::vector<char> layout_predictions;
  for (const ProbeSample* s : test) {
    const auto it = out.layout_rule.find(s->layout);
    layout_predictions.push_back(it == out.layout_rule.end() ? 's' : it->second);
  }
  out.scores.push_back(score_predictions("layout", 0.0, test, layout_predictions));
  // Episode ids for cross-validation.
  std::map<EpisodeKey, int> ids;
  for (const ProbeSample* s : train) ids.emplace(episode_key(*s), static_cast<int>(ids.size()));
  std::vector<int> labels, groups;
  for (const ProbeSample* s : train) {
    labels.push_back(exit_class(s->taken));
    groups.push_back(ids.at(episode_key(*s)));
  }
  for (int f = 0; f < kProbeFeatures; ++f) {
    const auto feature = static_cast<ProbeFeature>(f);
    std::vector<std::vector<float>> x;
    x.reserve(train.size());
    for (const ProbeSample* s : train) x.push_back(s->features(feature));
    const LinearProbe probe = LinearProbe::fit(x, labels, 3, groups);
    std::vector<char> predictions;
    for (const ProbeSample* s : test)
      predictions.push_back(exit_code(probe.predict(s->features(feature))));
    out.scores.push_back(score_predictions(to_string(feature), probe.lambda(), test, predictions));
  }
  return out;
}

}  // namespace

ProbeReport score_route_probe(const std::vector<ProbeSample>& samples,
                              const std::string& train_town, const std::string& other_town) {
  std::vector<const ProbeSample*> even, odd, all_train, other;
  for (const ProbeSample& s : samples) {
    if (s.town == train_town) {
      (s.episode % 2 == 0 ? even : odd).push_back(&s);
      all_train.push_back(&s);
    } else if (s.town == other_town) {
      other.push_back(&s);
    }
  }
  if (all_train.empty() || even.empty() || odd.empty()) {
    throw std::invalid_argument(
        "route probe: " + train_town +
        " needs samples from at least two episodes per cell (eval.episodes_per_cell >= 2): even "
        "episodes train the probe, odd ones test it");
  }
  ProbeReport report;
  report.evaluations.push_back(evaluate(train_town + ", held-out episodes",
                                        train_town + " even episodes", train_town + " odd episodes",
                                        even, odd));
  if (!other.empty()) {
    report.evaluations.push_back(
        evaluate("another town", "all of " + train_town, other_town, all_train, other));
  }
  return report;
}

std::string probe_settings(const config::Config& c) {
  const ProtocolGrid grid = protocol_grid(c);
  const EvalConfig eval = eval_config(c);
  auto join = [](const auto& items) {
    std::ostringstream text;
    for (size_t i = 0; i < items.size(); ++i) text << (i ? ", " : "") << items[i];
    return text.str();
  };
  return "Collected: the oracle at " + fixed(eval.oracle_speed_mps, 1) + " m/s, " +
         (eval.probe_oracle_brake
              ? "coasting behind leaders and for crossing traffic (eval.probe_oracle_brake)"
              : "never coasting") +
         "; states from " + fixed(eval.probe_far_m, 1) + " m to " + fixed(eval.probe_near_m, 1) +
         " m before each junction; towns " + join(grid.towns) + "; routes " + join(grid.routes) +
         "; densities " + join(grid.densities) + "; " + std::to_string(grid.episodes_per_cell) +
         " episodes per town x route x density.";
}

std::string write_probe_report(const ProbeReport& report, const std::filesystem::path& dir,
                               const std::string& title, const std::string& settings) {
  std::ostringstream md;
  md << "# " << title << "\n\n"
     << "Can the exit a route takes at a junction be read linearly from the snapshot's state in "
        "the last metres before it? Oracle drives, the snapshot's world model filters; ridge "
        "probes (lambda by cross-validation over training episodes). `layout`: the layout "
        "bound's rule, from a junction's exits alone; `action`: the oracle's previous action "
        "alone, a leak check that should stay at the layout's level. *followed*: share of test "
        "episodes whose every decision "
        "the probe got right (decision = majority of its steps), averaged over routes; an upper "
        "estimate of the average SR a policy taking its exits that way could reach. *places "
        "right*: distinct (route, junction) pairs most of whose test decisions are right, the "
        "sample size that counts (one place recurs in every episode of its route).\n";
  if (!settings.empty()) md << "\n" << settings << "\n";
  for (const ProbeEvaluation& e : report.evaluations) {
    std::set<std::string> routes;
    for (const auto& s : e.scores)
      for (const auto& [route, _] : s.route_followed) routes.insert(route);
    md << "\n## " << e.name << ": train " << e.train << " (" << e.train_samples << " steps), test "
       << e.test << " (" << e.test_samples << " steps)\n\n"
       << "| features | step accuracy | decisions | decision accuracy | places right | "
          "followed (mean over routes) |";
    for (const auto& route : routes) md << " " << route << " |";
    md << " lambda |\n|---|---|---|---|---|---|";
    for (size_t r = 0; r < routes.size(); ++r) md << "---|";
    md << "---|\n";
    for (const ProbeScore& s : e.scores) {
      md << "| " << s.features << " | " << fixed(100.0 * s.step_accuracy, 1) << "% | "
         << s.decisions << " | " << fixed(100.0 * s.decision_accuracy, 1) << "% | "
         << s.places_right << " / " << s.places << " | " << fixed(100.0 * s.mean_route_followed, 1)
         << "% |";
      for (const auto& route : routes) {
        const auto it = s.route_followed.find(route);
        md << " "
           << (it == s.route_followed.end() ? std::string("-") : fixed(100.0 * it->second, 1) + "%")
           << " |";
      }
      md << " " << (s.features == "layout" ? std::string("-") : fixed(s.lambda, 1)) << " |\n";
    }
    md << "\nLayout rule (the layout bound's, from the training decisions):";
    for (const auto& [layout, exit] : e.layout_rule) md << " {" << layout << "} -> " << exit << ";";
    md << "\n";
  }
  std::filesystem::create_directories(dir);
  const std::string text = md.str();
  std::ofstream(dir / "probe.md") << text;
  return text;
}

// ---------------------------------------------------------------------------------------------
// Collection.

struct RouteProbe::Impl {
  ProtocolGrid grid;
  agent::AgentConfig agent_config;
  std::unique_ptr<agent::Policy> policy;
  std::unique_ptr<EpisodePolicy> oracle;
  std::unique_ptr<env::Env> env;
  double near_m = 6.0, far_m = 14.0;
  double budget_speed_mps = 3.0, budget_slack = 1.5;
};

RouteProbe::RouteProbe(const service::ServiceConfig& service) : impl_(std::make_unique<Impl>()) {
  const EvalConfig eval = eval_config(service.config());
  impl_->grid = protocol_grid(service.config());
  impl_->near_m = eval.probe_near_m;
  impl_->far_m = eval.probe_far_m;
  if (impl_->near_m >= impl_->far_m) {
    throw EvalError("eval.probe_near_m (" + fixed(impl_->near_m, 1) +
                    ") must be below eval.probe_far_m (" + fixed(impl_->far_m, 1) + ")");
  }
  impl_->budget_speed_mps = eval.budget_speed_mps;
  impl_->budget_slack = eval.budget_slack;
  const std::string& given = eval.snapshot_file;
  if (given.empty()) throw EvalError("the route probe needs a snapshot file: --snapshot FILE");
  const std::string file_name = snapshot_file_path(given);
  const PolicyHead head = resolve_head(eval.head, eval.kind);
  const agent::SnapshotFile file = agent::read_snapshot_file(file_name);
  const std::string source = "snapshot file " + file_name;
  impl_->agent_config = service.agent();
  const std::string note =
      adopt_snapshot_architecture(impl_->agent_config, file, service.agent_choices(), source);
  if (!note.empty()) {
    INDRIVE_LOG(kInfo, "probe") << note;
  }
  check_snapshot_head(file.blob, head, source);
  const agent::AgentConfig acting = acting_config(impl_->agent_config, head);
  try {
    impl_->policy = std::make_unique<agent::Policy>(acting);
    impl_->policy->load_snapshot(file.blob);
  } catch (const std::exception& error) {
    throw EvalError(source + " does not fit the configured model (preset " + acting.preset +
                    "): " + error.what());
  }
  impl_->policy->keep_embedding(true);
  impl_->oracle = make_oracle_policy(
      {.target_speed_mps = eval.oracle_speed_mps, .brake_for_leader = eval.probe_oracle_brake});
  env::EnvConfig config = protocol_env_config(actor::env_config(service, impl_->agent_config));
  config.town = impl_->grid.towns.front();
  impl_->env = std::make_unique<env::Env>(config);
}

RouteProbe::~RouteProbe() = default;

std::vector<ProbeSample> RouteProbe::collect(const std::atomic<bool>& stop) {
  Impl& m = *impl_;
  std::vector<ProbeSample> samples;
  const auto episodes = m.grid.all_episodes();
  const auto started = std::chrono::steady_clock::now();
  int done = 0;
  for (const EpisodeSpec& spec : episodes) {
    if (stop.load()) break;
    env::StepResult step =
        m.env->reset({.town = spec.town,
                      .route = spec.route,
                      .density = spec.density,
                      .traffic_seed = static_cast<std::uint64_t>(spec.traffic_seed),
                      .spawn_seed = static_cast<std::uint64_t>(spec.spawn_seed)});
    const env::Route& route = *m.env->route();
    const std::vector<ChoicePoint> points = choice_points(m.env->town().net, route);
    const int budget = route_step_budget(route.length_m(), m.budget_speed_mps, m.budget_slack);
    m.oracle->begin(*m.env, spec);
    m.policy->reseed(spec.policy_seed);
    agent::PolicyState state;
    while (!step.is_last && step.step < budget && !stop.load()) {
      // The snapshot filters the frame as when it acts; the oracle's action is what was done.
      const int previous = step.is_first ? 0 : state.action;
      m.policy->act(std::span<const std::uint8_t>(step.observation.data, step.observation.total()),
                    step.is_first, state, /*sample=*/false);
      state.action = previous;  // act() put its own choice there
      const double along = route.is_loop() ? std::fmod(step.route_progress_m, route.length_m())
                                           : step.route_progress_m;
      for (size_t p = 0; p < points.size(); ++p) {
        const double ahead = points[p].junction_s_m - along;
        if (ahead < m.near_m || ahead > m.far_m) continue;
        ProbeSample sample;
        sample.town = spec.town;
        sample.route = spec.route;
        sample.density = spec.density;
        sample.episode = spec.episode;
        sample.decision = static_cast<int>(p);
        sample.approach = points[p].approach;
        sample.layout = points[p].layout;
        sample.taken = points[p].taken;
        sample.to_junction_m = ahead;
        sample.previous_action = state.action;
        sample.view = m.policy->last_embedding();
        sample.memory = state.deter;
        sample.latent = state.stoch;
        samples.push_back(std::move(sample));
        break;
      }
      const int action = m.oracle->act(*m.env, step);
      state.action = action;
      step = m.env->step(action);
    }
    ++done;
    const double elapsed =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
    INDRIVE_LOG(kInfo, "probe") << "episode " << done << "/" << episodes.size() << " (" << spec.town
                                << " " << spec.route << " density " << spec.density
                                << "): " << step.step << " steps, " << samples.size()
                                << " samples so far, " << fixed(elapsed, 0) << " s, about "
                                << fixed(elapsed / done * (episodes.size() - done), 0)
                                << " s to go";
  }
  return samples;
}

}  // namespace indrive::route_probe
