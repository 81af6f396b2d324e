// A small road network for the sim tests, converted from plain XML by netconvert.
//
// Layout (metres): a two-way east-west road from W (0,0) through the T-junction C (150,0) to
// E (300,0), and a two-way branch from C north to N (150,150). One lane per direction,
// 3.5 m wide, right-hand traffic. Normal edges: "we" and "ew" (W<->C), "ce"/"ec" (C<->E),
// "cn"/"nc" (C<->N).
#pragma once

#include <filesystem>

namespace indrive::testing {

// Writes the plain XML into dir and converts it; returns the .net.xml path. Fails the
// calling test (ADD_FAILURE) and returns an empty path if netconvert fails.
std::filesystem::path make_t_junction_net(const std::filesystem::path& dir);

}  // namespace indrive::testing
