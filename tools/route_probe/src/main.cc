// indrive-route-probe: does what a snapshot's policy sees tell which exit its route takes at a
// junction? The oracle drives the grid's routes, the snapshot only watches, and linear probes
// from its view, memory and latent state to each route's exits are scored against the layout
// rule (include/indrive/route_probe/route_probe.h; docs/evaluation.md, "Where the bound binds").
#include <CLI/CLI.hpp>
#include <algorithm>
#include <cstdio>
#include <stdexcept>

#include "indrive/actor/evaluator.h"
#include "indrive/basics/log.h"
#include "indrive/route_probe/route_probe.h"
#include "indrive/service/process_cli.h"

int main(int argc, char** argv) {
  CLI::App app{
      "indrive-route-probe: drive the grid's routes with the oracle and measure whether a "
      "snapshot's state tells the exit each route takes at its junctions; writes "
      "<run>/probe/probe.md"};
  // The run's configuration as the service programs take it, less their DDS options: the
  // probe runs on its own and talks to no learner.
  indrive::service::ServiceOptions options;
  std::string log_level = "info";
  app.add_option("--config", options.config_file, "run configuration (YAML)")
      ->check(CLI::ExistingFile);
  app.add_option("--run-dir", options.run_dir, "run directory; the report goes to <run>/probe/")
      ->required();
  app.add_option("--set", options.overrides, "config override key=value (repeatable)");
  app.add_option("--log-level", log_level, "debug, info, warn, error or off")
      ->capture_default_str();
  std::string snapshot;
  std::string train_town = "town01";
  app.add_option("--snapshot", snapshot,
                 "the snapshot file (eval.snapshot_file) whose state is probed, or a run "
                 "directory's final-snapshot.params; the model's preset and sizes come from the "
                 "file")
      ->required();
  app.add_option("--train-town", train_town,
                 "town whose even episodes train the probe (odd ones test it); the grid's other "
                 "town tests the probe trained on all of it")
      ->capture_default_str();
  CLI11_PARSE(app, argc, argv);

  try {
    indrive::log::set_level(indrive::log::parse_level(log_level));
    const auto& stop = indrive::service::install_stop_signals();
    options.overrides.push_back("eval.snapshot_file=" + snapshot);
    const auto config = indrive::service::ServiceConfig::resolve(options);
    const auto towns = indrive::actor::protocol_grid(config.config()).towns;
    if (std::find(towns.begin(), towns.end(), train_town) == towns.end()) {
      throw std::invalid_argument("--train-town " + train_town +
                                  " is not among the grid's towns (eval.towns); add it there");
    }
    indrive::route_probe::RouteProbe probe(config);
    const auto samples = probe.collect(stop);
    if (stop.load()) return 0;
    std::string other;
    for (const auto& town : towns)
      if (town != train_town && other.empty()) other = town;
    const auto report = indrive::route_probe::score_route_probe(samples, train_town, other);
    const std::string text = indrive::route_probe::write_probe_report(
        report, config.run_dir() / "probe", "Route probe of " + snapshot,
        indrive::route_probe::probe_settings(config.config()));
    std::printf("%s", text.c_str());
    return 0;
  } catch (const std::exception& error) {
    INDRIVE_LOG(kError, "probe") << "indrive-route-probe failed: " << error.what();
    return 1;
  }
}
