// indrive-learner: the learner of one run. Started by `indrive launch`; see
// docs/architecture.md, section 2. Prints one progress line per log interval.
#include <CLI/CLI.hpp>
#include <cstdio>
#include <optional>

#include "indrive/basics/data_path.h"
#include "indrive/basics/log.h"
#include "indrive/learner/learner.h"
#include "indrive/learner/learner_config.h"
#include "indrive/learner/page_writer.h"
#include "indrive/service/process_cli.h"

int main(int argc, char** argv) {
  CLI::App app{"indrive-learner: trains the agent on the actors' trajectories"};
  indrive::service::ServiceOptions options;
  std::string log_level = "info";
  indrive::service::add_service_options(app, options, log_level);
  CLI11_PARSE(app, argc, argv);

  // The run's page, kept by a companion `indrive dashboard` beside this program; it outlives
  // the learner object so that it can say how the run ended, even when the learner throws.
  std::optional<indrive::learner::PageWriter> page;
  try {
    indrive::log::set_level(indrive::log::parse_level(log_level));
    const auto& stop = indrive::service::install_stop_signals();
    const auto config = indrive::service::ServiceConfig::resolve(options);
    if (options.check_only) {
      std::printf("%s\n", indrive::service::check_summary(config, "learner").c_str());
      return 0;
    }
    if (const double every_s = indrive::learner::learner_config(config.config()).dashboard_s;
        every_s > 0) {
      page.emplace(indrive::own_program_folder() / "indrive", config.run_dir(), every_s);
    }
    indrive::learner::Learner learner(config);
    learner.on_progress([](const std::string& line) {
      std::printf("%s\n", line.c_str());
      std::fflush(stdout);
    });
    const int code = learner.run(stop);
    if (page) {
      const auto& counters = learner.stats().counters;
      page->finish(indrive::learner::training_ended(stop.load(), counters.env_steps,
                                                    counters.updates, "learner", code));
    }
    return code;
  } catch (const std::exception& error) {
    INDRIVE_LOG(kError, "learner") << "indrive-learner failed: " << error.what();
    if (page) page->finish(std::string("ended: the learner failed: ") + error.what());
    return 1;
  }
}
