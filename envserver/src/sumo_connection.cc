// What both SUMO clients share: mode parsing, the command line, the factory.
#include <filesystem>
#include <string>
#include <vector>

#include "indrive/envserver/sumo.h"
#include "sumo_clients.h"

namespace indrive::env {

SumoMode parse_sumo_mode(std::string_view text) {
  if (text == "libsumo") return SumoMode::kLibsumo;
  if (text == "libtraci") return SumoMode::kLibtraci;
  throw SumoError("unknown sumo.mode '" + std::string(text) +
                  "'; use libsumo (in-process) or libtraci (sumo subprocess over TCP)");
}

std::vector<std::string> sumo_arguments(const SumoConfig& config,
                                        const std::filesystem::path& net_file, std::uint64_t seed) {
  std::vector<std::string> args = {
      "--net-file",
      net_file.string(),
      "--step-length",
      std::to_string(config.step_length_s),
      "--seed",
      std::to_string(seed % 2147483647u),  // SUMO takes a signed 32-bit seed
      "--begin",
      "0",
      // Vehicles must never jump: a stuck vehicle stays where it is.
      "--time-to-teleport",
      "-1",
      // Collisions are reported, not resolved by SUMO: the environment ends the episode.
      "--collision.action",
      "warn",
      "--collision.check-junctions",
      "true",
      "--collision.mingap-factor",
      "0",
      // Schema files live under SUMO_HOME, which a plain install may lack.
      "--xml-validation",
      "never",
      "--xml-validation.net",
      "never",
      "--no-step-log",
      "true",
      "--no-warnings",
      "true",
      "--duration-log.disable",
      "true",
      "--verbose",
      "false",
  };
  if (config.lateral_resolution_m > 0.0) {
    // Sublanes let a car going straight see a vehicle on a diverging (turning) link from the
    // same lane while the two still overlap sideways; without them it drives into the rear of
    // a slow ego that has just started its turn.
    args.push_back("--lateral-resolution");
    args.push_back(std::to_string(config.lateral_resolution_m));
  }
  args.insert(args.end(), config.extra_args.begin(), config.extra_args.end());
  return args;
}

std::unique_ptr<SumoConnection> make_sumo_connection(const SumoConfig& config) {
  if (!(config.step_length_s > 0.0)) {
    throw SumoError("sumo.step_length_s must be positive, got " +
                    std::to_string(config.step_length_s));
  }
  if (config.mode == SumoMode::kLibsumo) return detail::make_libsumo_connection(config);

  SumoConfig resolved = config;
  if (resolved.sumo_binary.empty()) resolved.sumo_binary = INDRIVE_SUMO_BINARY;
  std::error_code ec;
  if (!std::filesystem::is_regular_file(resolved.sumo_binary, ec)) {
    throw SumoError("sumo binary '" + resolved.sumo_binary.string() +
                    "' not found; install the sumo package or set sumo.binary to its path "
                    "(libtraci mode starts it as a subprocess)");
  }
  return detail::make_libtraci_connection(resolved);
}

}  // namespace indrive::env
