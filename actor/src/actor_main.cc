// indrive-actor: a training actor (--id I) or an evaluator (--evaluate --id J --of M) of one
// run. Started by `indrive launch`; see docs/architecture.md, section 2.
#include <CLI/CLI.hpp>
#include <cstdio>
#include <stdexcept>

#include "indrive/actor/evaluator.h"
#include "indrive/actor/policies.h"
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
  CLI11_PARSE(app, argc, argv);

  try {
    indrive::log::set_level(indrive::log::parse_level(log_level));
    const auto& stop = indrive::service::install_stop_signals();
    if (!evaluate && (!policy.empty() || !snapshot.empty() || continuous)) {
      throw std::invalid_argument("--policy, --snapshot and --continuous need --evaluate");
    }
    // The flags are shorthands for eval.* keys, applied after any --set.
    if (!policy.empty()) {
      indrive::actor::parse_policy_source(policy);  // names the allowed values for the flag
      options.overrides.push_back("eval.policy=" + policy);
    }
    if (!snapshot.empty()) {
      options.overrides.push_back("eval.snapshot_file=" + snapshot);
      if (policy.empty()) options.overrides.push_back("eval.policy=snapshot");
    }
    if (continuous) options.overrides.push_back("eval.continuous=true");
    const auto config = indrive::service::ServiceConfig::resolve(options);
    if (options.check_only) {
      const char* role = evaluate ? "evaluator" : "actor";
      std::printf("%s\n", indrive::service::check_summary(config, role).c_str());
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
