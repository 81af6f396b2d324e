// indrive-learner: the learner of one run. Started by `indrive launch`; see
// docs/architecture.md, section 2. Prints one progress line per log interval.
#include <CLI/CLI.hpp>
#include <cstdio>

#include "indrive/actor/process_cli.h"
#include "indrive/common/log.h"
#include "indrive/learner/learner.h"

int main(int argc, char** argv) {
  CLI::App app{"indrive-learner: trains the agent on the actors' trajectories"};
  indrive::actor::ServiceOptions options;
  std::string log_level = "info";
  indrive::actor::add_service_options(app, options, log_level);
  CLI11_PARSE(app, argc, argv);

  try {
    indrive::log::set_level(indrive::log::parse_level(log_level));
    const auto& stop = indrive::actor::install_stop_signals();
    const auto config = indrive::actor::ServiceConfig::resolve(options);
    if (options.check_only) {
      std::printf("%s\n", indrive::actor::check_summary(config, "learner").c_str());
      return 0;
    }
    indrive::learner::Learner learner(config);
    learner.on_progress([](const std::string& line) {
      std::printf("%s\n", line.c_str());
      std::fflush(stdout);
    });
    return learner.run(stop);
  } catch (const std::exception& error) {
    INDRIVE_LOG(kError, "learner") << "indrive-learner failed: " << error.what();
    return 1;
  }
}
