// indrive-train-local: one run of any phase in one process, with the flags and config keys of
// the service processes, for debugging, the end-to-end smoke test and the exploration study.
//
//   indrive-train-local --config deploy/configs/pretrain_disag.yaml --run-dir runs/local-disag
//   indrive-train-local --config deploy/configs/pretrain_disag.yaml --run-dir runs/rnd --random
//   indrive-train-local --config deploy/configs/finetune_lf.yaml --run-dir runs/local-lf
//       --set learner.init_checkpoint=runs/local-disag/checkpoints/ckpt-000000015625.bin
//   indrive-train-local --config deploy/configs/finetune_lf.yaml --run-dir runs/local-lf
//       --evaluate-episodes 10 --route straight
// SIGINT / SIGTERM save a checkpoint and exit; running again resumes from it.
#include <CLI/CLI.hpp>
#include <cstdio>
#include <optional>

#include "indrive/actor/env_adapter.h"
#include "indrive/basics/data_path.h"
#include "indrive/basics/log.h"
#include "indrive/learner/learner_config.h"
#include "indrive/learner/page_writer.h"
#include "indrive/local/local_run.h"
#include "indrive/service/process_cli.h"

int main(int argc, char** argv) {
  CLI::App app{"indrive-train-local: environment, replay and training in one process"};
  indrive::service::ServiceOptions options;
  std::string log_level = "info";
  bool random = false;
  int evaluate_episodes = 0;
  std::string route;
  indrive::service::add_service_options(app, options, log_level);
  app.add_flag("--random", random,
               "act randomly throughout and never train (same as --set "
               "local.random=true)");
  app.add_option("--evaluate-episodes", evaluate_episodes,
                 "evaluate the newest checkpoint instead of training: this many episodes per "
                 "density of eval.densities, with the protocol's seeds")
      ->check(CLI::Range(1, 100000));
  app.add_option("--route", route,
                 "route(s) to evaluate on, comma-separated (and to train on: sets env.route)");
  CLI11_PARSE(app, argc, argv);

  // The run's page, as the learner keeps it (learner.dashboard_s): a companion `indrive
  // dashboard` told how the training ended.
  std::optional<indrive::learner::PageWriter> page;
  try {
    indrive::log::set_level(indrive::log::parse_level(log_level));
    if (random) options.overrides.push_back("local.random=true");
    if (!route.empty()) options.overrides.push_back("env.route=" + route);
    const auto& stop = indrive::service::install_stop_signals();
    const auto config = indrive::service::ServiceConfig::resolve(options);
    if (options.check_only) {
      // The local trainer runs no DDS participant: its summary names the profiles it would
      // resolve, but no security role is checked.
      std::printf("%s\n", indrive::service::check_summary(config, "").c_str());
      return 0;
    }
    if (evaluate_episodes > 0) {
      if (route.empty()) route = indrive::actor::EnvAdapter::options_from(config).route;
      if (route.empty()) route = "straight";
      // env.route may list several routes (task runs draw one per episode): each is evaluated.
      for (const std::string& name : indrive::actor::route_list(route)) {
        const auto summary =
            indrive::local::evaluate_locally(config, name, evaluate_episodes, stop);
        std::printf("evaluation %s %s: SR %.1f%% (%d/%d), route completion %.3f, %.1f steps\n",
                    config.run_id().c_str(), name.c_str(), 100.0 * summary.success_rate,
                    summary.successes, summary.episodes, summary.mean_route_completion,
                    summary.mean_steps);
      }
      return 0;
    }
    if (const double every_s = indrive::learner::learner_config(config.config()).dashboard_s;
        every_s > 0) {
      page.emplace(indrive::own_program_folder() / "indrive", config.run_dir(), every_s);
    }
    indrive::local::LocalRun run(config);
    run.on_progress([](const std::string& line) {
      std::puts(line.c_str());
      std::fflush(stdout);
    });
    run.train(stop);
    std::printf(
        "done %s: %lld env steps, %lld updates, coverage %.2f distinct segments per 1k "
        "steps, %.2f%% of the town's segments\n",
        config.run_id().c_str(), static_cast<long long>(run.env_steps()),
        static_cast<long long>(run.updates()), run.coverage().distinct_per_window(),
        100.0 * run.coverage().fraction_visited());
    if (page) {
      page->finish(indrive::learner::training_ended(stop.load(), run.env_steps(), run.updates(),
                                                    "indrive-train-local", 0));
    }
    return 0;
  } catch (const std::exception& error) {
    INDRIVE_LOG(kError, "local") << "indrive-train-local failed: " << error.what();
    if (page) page->finish(std::string("ended: indrive-train-local failed: ") + error.what());
    return 1;
  }
}
