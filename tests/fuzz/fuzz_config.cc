// A run configuration as every process resolves it: a YAML file plus --set overrides, then the
// agent and environment settings derived from it.
// Input: YAML text; a line "--set" ends it and each later line is one override (key=value).
#include <cstdint>
#include <string>
#include <vector>

#include "fuzz_support.h"
#include "indrive/actor/env_adapter.h"
#include "indrive/basics/config.h"
#include "indrive/service/run_config.h"

namespace {

using namespace indrive;

void make_seeds(const fuzz::fs::path& dir) {
  const fuzz::fs::path configs = fuzz::fs::path(INDRIVE_SOURCE_DIR) / "deploy" / "configs";
  for (const auto& entry : fuzz::fs::directory_iterator(configs)) {
    if (entry.path().extension() != ".yaml") continue;
    std::string text = fuzz::read_text(entry.path());
    text += "\n--set\nagent.world_model.deter=64\nenv.densities=5,10\nrun.seed=3\n";
    fuzz::write_seed(dir, entry.path().stem().string(), text);
  }
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) { return fuzz::initialize(make_seeds); }

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string input(fuzz::text(data, size));
  std::string yaml = input;
  service::ServiceOptions options;
  if (const auto split = input.find("\n--set\n"); split != std::string::npos) {
    yaml = input.substr(0, split);
    std::size_t begin = split + 7;
    while (begin <= input.size()) {
      const std::size_t end = std::min(input.find('\n', begin), input.size());
      options.overrides.push_back(input.substr(begin, end - begin));
      begin = end + 1;
    }
  }
  options.config_file =
      fuzz::as_file(reinterpret_cast<const std::uint8_t*>(yaml.data()), yaml.size(), ".yaml");
  options.run_dir = "runs/fuzz";
  fuzz::accept<config::ConfigError, agent::AgentConfigError>([&] {
    const auto service = service::ServiceConfig::resolve(options);
    service.agent_choices();
    actor::env_config(service);
    service.wire_phase();
  });
  return 0;
}
