// indrive-actor: a training actor (--id I) or an evaluator (--evaluate --id J --of M) of one
// run. Started by `indrive launch`; see docs/architecture.md, section 2.
#include <CLI/CLI.hpp>
#include <algorithm>
#include <cstdio>
#include <stdexcept>

#include "indrive/actor/evaluator.h"
#include "indrive/actor/policies.h"
#include "indrive/actor/route_probe.h"
#include "indrive/actor/training_actor.h"
#include "indrive/basics/log.h"
#include "indrive/service/process_cli.h"

int main(int argc, char** argv) {
  CLI::App app{"indrive-actor: steps one environment for the learner, or evaluates snapshots"};
  indrive::service::ServiceOptions options;
  std::string log_level = "info";
  int id = 0;
  int of = 1;
  bool evaluate = false;
  indrive::service::add_service_options(app, options, log_level);
  app.add_option("--id", id, "actor id (training) or evaluator index")->check(CLI::Range(0, 1023));
  app.add_option("--of", of, "number of evaluators sharing the protocol grid")
      ->check(CLI::Range(1, 1024));
  app.add_flag("--evaluate", evaluate, "run the evaluation protocol instead of training");
  std::string policy;
  std::string snapshot;
  bool continuous = false;
  app.add_option("--policy", policy, "evaluation policy: snapshot, oracle or random (eval.policy)");
  app.add_option("--snapshot", snapshot,
                 "evaluate this snapshot file (eval.snapshot_file) instead of the learner's, or "
                 "a run directory's final-snapshot.params; the model's preset and sizes come "
                 "from the file");
  app.add_flag("--continuous", continuous,
               "evaluate every eval.every_k-th new snapshot into a learning curve");
  bool probe = false;
  std::string probe_town = "town01";
  app.add_flag("--probe", probe,
               "with --snapshot: drive the grid's routes with the oracle and measure whether the "
               "snapshot's state tells the exit each route takes at its junctions; writes "
               "<run>/probe/probe.md (actor/include/indrive/actor/route_probe.h)");
  app.add_option("--probe-train-town", probe_town,
                 "town whose even episodes train the probe (odd ones test it); the grid's other "
                 "town tests the probe trained on all of it")
      ->capture_default_str();
  CLI11_PARSE(app, argc, argv);

  try {
    indrive::log::set_level(indrive::log::parse_level(log_level));
    const auto& stop = indrive::service::install_stop_signals();
    if (!evaluate && !probe && (!policy.empty() || !snapshot.empty() || continuous)) {
      throw std::invalid_argument("--policy, --snapshot and --continuous need --evaluate");
    }
    if (probe && (evaluate || continuous || snapshot.empty() || !policy.empty())) {
      throw std::invalid_argument(
          "--probe needs --snapshot FILE and takes neither --evaluate, --continuous nor --policy "
          "(the oracle drives, the snapshot only watches)");
    }
    // The flags are shorthands for eval.* keys, applied after any --set.
    if (!policy.empty()) {
      indrive::actor::parse_policy_source(policy);  // names the allowed values for the flag
      options.overrides.push_back("eval.policy=" + policy);
    }
    if (!snapshot.empty()) {
      options.overrides.push_back("eval.snapshot_file=" + snapshot);
      if (policy.empty() && !probe) options.overrides.push_back("eval.policy=snapshot");
    }
    if (continuous) options.overrides.push_back("eval.continuous=true");
    const auto config = indrive::service::ServiceConfig::resolve(options);
    if (options.check_only) {
      const char* role = evaluate ? "evaluator" : "actor";
      std::printf("%s\n", indrive::service::check_summary(config, role).c_str());
      return 0;
    }
    if (probe) {
      const auto towns = indrive::actor::protocol_grid(config.config()).towns;
      if (std::find(towns.begin(), towns.end(), probe_town) == towns.end()) {
        throw std::invalid_argument("--probe-train-town " + probe_town +
                                    " is not among the grid's towns (eval.towns); add it there");
      }
      indrive::actor::RouteProbe route_probe(config);
      const auto samples = route_probe.collect(stop);
      if (stop.load()) return 0;
      std::string other;
      for (const auto& town : towns)
        if (town != probe_town && other.empty()) other = town;
      const auto report = indrive::actor::score_route_probe(samples, probe_town, other);
      const std::string text = indrive::actor::write_probe_report(
          report, config.run_dir() / "probe", "Route probe of " + snapshot,
          indrive::actor::probe_settings(config.config()));
      std::printf("%s", text.c_str());
      return 0;
    }
    if (evaluate) {
      indrive::actor::Evaluator evaluator(config, id, of);
      return evaluator.run(stop);
    }
    indrive::actor::TrainingActor actor(config, static_cast<std::uint32_t>(id));
    actor.run(stop);
    return 0;
  } catch (const std::exception& error) {
    INDRIVE_LOG(kError, "actor") << "indrive-actor failed: " << error.what();
    return 1;
  }
}
