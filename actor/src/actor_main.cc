// indrive-actor: a training actor (--id I) or an evaluator (--evaluate --id J --of M) of one
// run. Started by `indrive launch`; see docs/architecture.md, section 2.
#include <CLI/CLI.hpp>
#include <cstdio>

#include "indrive/actor/evaluator.h"
#include "indrive/actor/process_cli.h"
#include "indrive/actor/training_actor.h"
#include "indrive/common/log.h"

int main(int argc, char** argv) {
  CLI::App app{"indrive-actor: steps one environment for the learner, or evaluates snapshots"};
  indrive::actor::ServiceOptions options;
  std::string log_level = "info";
  int id = 0;
  int of = 1;
  bool evaluate = false;
  indrive::actor::add_service_options(app, options, log_level);
  app.add_option("--id", id, "actor id (training) or evaluator index")->check(CLI::Range(0, 1023));
  app.add_option("--of", of, "number of evaluators sharing the protocol grid")
      ->check(CLI::Range(1, 1024));
  app.add_flag("--evaluate", evaluate, "run the evaluation protocol instead of training");
  CLI11_PARSE(app, argc, argv);

  try {
    indrive::log::set_level(indrive::log::parse_level(log_level));
    const auto& stop = indrive::actor::install_stop_signals();
    const auto config = indrive::actor::ServiceConfig::resolve(options);
    if (options.check_only) {
      std::printf("%s\n", indrive::actor::check_summary(config).c_str());
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
