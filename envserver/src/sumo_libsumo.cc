// SumoConnection over libsumo: SUMO runs inside this process.
#include <libsumo/libsumo.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <csignal>
#include <cstring>
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

// SUMO's own assertions abort the process that runs libsumo. The handler below names the
// network that was loaded and the way out before the process ends: written with write(2) from
// buffers filled at load time, as a signal handler may do.
char g_network[1024] = "";
std::atomic<std::size_t> g_network_length{0};
std::atomic<bool> g_handler_installed{false};

void write_all(const char* text, std::size_t length) {
  while (length > 0) {
    const ssize_t n = ::write(STDERR_FILENO, text, length);
    if (n <= 0) return;
    text += n;
    length -= static_cast<std::size_t>(n);
  }
}

extern "C" void on_abort(int signal_number) {
  if (g_libsumo_in_use.load()) {
    static constexpr char kHead[] =
        "\nThis process aborted while SUMO ran inside it (libsumo) on network ";
    static constexpr char kTail[] =
        ". If the assertion above names a SUMO source (src/microsim/...), SUMO failed on this "
        "map: run with --set env.sumo_mode=libtraci, where SUMO runs as a child process and a "
        "fault there ends only the episode (env_fault), and report the map.\n";
    write_all(kHead, sizeof kHead - 1);
    write_all(g_network, g_network_length.load());
    write_all(kTail, sizeof kTail - 1);
  }
  std::signal(signal_number, SIG_DFL);
  std::raise(signal_number);
}

void note_network(const std::vector<std::string>& args) {
  const auto it = std::find(args.begin(), args.end(), "--net-file");
  const std::string network = it != args.end() && it + 1 != args.end() ? *(it + 1) : "?";
  g_network_length.store(0);
  const std::size_t length = std::min(network.size(), sizeof g_network);
  std::memcpy(g_network, network.data(), length);
  g_network_length.store(length);
  if (!g_handler_installed.exchange(true)) std::signal(SIGABRT, on_abort);
}

}  // namespace

void LibsumoConnection::start(const std::vector<std::string>& args) {
  note_network(args);
  std::vector<std::string> command{"sumo"};  // libsumo ignores the program name
  command.insert(command.end(), args.begin(), args.end());
  libsumo::Simulation::start(command);
}

void LibsumoConnection::loading(const std::vector<std::string>& args) { note_network(args); }

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
