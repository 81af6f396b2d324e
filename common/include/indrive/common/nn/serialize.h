// Serialization of named parameter groups to a byte blob, the format of DDS policy snapshots and
// checkpoints.
//
// Layout (little-endian): magic "INNP", u32 version, u32 group count; per group: name, u32
// parameter count; per parameter: name, u32 rank, i64 dims[rank], f32 data[numel]; then the
// CRC-32 of every preceding byte. Names are u32 length + bytes.
#pragma once

#include <cstdint>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

#include "indrive/common/nn/tensor.h"

namespace indrive::nn {

// A blob does not match what the loader expects (corrupt, truncated, wrong names or shapes).
// The message says which group/parameter and what was expected.
class SerializationError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Serializes the groups (names, shapes, values) into one blob with a trailing checksum.
std::vector<std::uint8_t> save_params(std::span<const ParamGroup* const> groups);
// Serializes one group.
std::vector<std::uint8_t> save_params(const ParamGroup& group);
// Loads values into the groups; the blob must hold exactly these groups with the same parameter
// names and shapes in the same order. Throws SerializationError otherwise; the groups are left
// unchanged when loading fails.
void load_params(std::span<const std::uint8_t> blob, std::span<ParamGroup* const> groups);
// Loads one group.
void load_params(std::span<const std::uint8_t> blob, ParamGroup& group);

}  // namespace indrive::nn
