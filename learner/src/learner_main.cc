// indrive-learner: the learner of one run. Started by `indrive launch`; see
// docs/architecture.md, section 2. Prints one progress line per log interval.
#include <CLI/CLI.hpp>
#include <cstdio>

#include "indrive/basics/log.h"
#include "indrive/learner/learner.h"
#include "indrive/service/process_cli.h"

int main(int argc, char** argv) {
  CLI::App app{"indrive-learner: trains the agent on the actors' trajectories"};
  indrive::service::ServiceOptions options;
  std::string log_level = "info";
  indrive::service::add_service_options(app, options, log_level);
  CLI11_PARSE(app, argc, argv);

  try {
    indrive::log::set_level(indrive::log::parse_level(log_level));
    const auto& stop = indrive::service::install_stop_signals();
    const auto config = indrive::service::ServiceConfig::resolve(options);
    if (options.check_only) {
      std::printf("%s\n", indrive::service::check_summary(config, "learner").c_str());
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
