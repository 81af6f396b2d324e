// SumoConnection over libsumo: SUMO runs inside this process.
#include <libsumo/libsumo.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <sstream>
#include <unordered_map>
#include <unordered_set>

#include "indrive/basics/check.h"
#include "sumo_clients.h"

#define INDRIVE_SUMO_API libsumo
#define INDRIVE_SUMO_CLASS LibsumoConnection
#include "sumo_client_impl.inc"

namespace indrive::env::detail {
namespace {

// libsumo keeps the simulation in process-wide state, so a process can run only one.
std::atomic<bool> g_libsumo_in_use{false};

}  // namespace

void LibsumoConnection::start(const std::vector<std::string>& args) {
  std::vector<std::string> command{"sumo"};  // libsumo ignores the program name
  command.insert(command.end(), args.begin(), args.end());
  libsumo::Simulation::start(command);
}

void LibsumoConnection::select() {}

void LibsumoConnection::release() { g_libsumo_in_use.store(false); }

std::unique_ptr<SumoConnection> make_libsumo_connection(const SumoConfig& config) {
  if (g_libsumo_in_use.exchange(true)) {
    throw SumoError(
        "libsumo runs one simulation per process and one is already open; close it first or "
        "use sumo.mode: libtraci for several simulations in one process");
  }
  return std::make_unique<LibsumoConnection>(config);
}

}  // namespace indrive::env::detail
