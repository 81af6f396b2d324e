// Factories of the two SUMO client implementations (sumo_libsumo.cc, sumo_libtraci.cc).
#pragma once

#include <memory>

#include "indrive/envserver/sumo.h"

namespace indrive::env::detail {

std::unique_ptr<SumoConnection> make_libsumo_connection(const SumoConfig& config);
std::unique_ptr<SumoConnection> make_libtraci_connection(const SumoConfig& config);

}  // namespace indrive::env::detail
