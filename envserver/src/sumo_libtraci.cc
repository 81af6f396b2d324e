// SumoConnection over libtraci: SUMO runs as a subprocess, driven over TCP.
#include <libsumo/libtraci.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <csignal>
#include <sstream>
#include <unordered_map>
#include <unordered_set>

#include "indrive/basics/check.h"
#include "sumo_clients.h"

#define INDRIVE_SUMO_API libtraci
#define INDRIVE_SUMO_CLASS LibtraciConnection
#include "sumo_client_impl.inc"

namespace indrive::env::detail {
namespace {

std::atomic<int> g_next_label{0};

}  // namespace

void LibtraciConnection::start(const std::vector<std::string>& args) {
  // A SUMO that died leaves a closed socket, and writing to it would end this process with
  // SIGPIPE; ignored, the write fails, the call throws and the episode ends as env_fault.
  std::signal(SIGPIPE, SIG_IGN);
  std::vector<std::string> command{config_.sumo_binary.string()};
  command.insert(command.end(), args.begin(), args.end());
  // Each connection has its own label, so several simulations can live in one process.
  label_ = "indrive" + std::to_string(g_next_label.fetch_add(1));
  // A free port is picked by libtraci (-1); a few retries cover a slow subprocess start.
  libtraci::Simulation::start(command, -1, 60, label_);
}

void LibtraciConnection::select() {
  // After another connection closed there is no active one, and asking for its label would
  // dereference nothing (the crash when a test closed two simulations in a row).
  if (!libtraci::Simulation::isLoaded() || libtraci::Simulation::getLabel() != label_) {
    libtraci::Simulation::switchConnection(label_);
  }
}

void LibtraciConnection::release() {}

void LibtraciConnection::loading(const std::vector<std::string>&) {}

std::unique_ptr<SumoConnection> make_libtraci_connection(const SumoConfig& config) {
  return std::make_unique<LibtraciConnection>(config);
}

}  // namespace indrive::env::detail
