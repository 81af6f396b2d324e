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

#include "indrive/nn/tensor.h"

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

// One parameter as a blob states it.
struct BlobParam {
  std::string name;
  Shape shape;
};
// One group as a blob states it.
struct BlobGroup {
  std::string name;
  std::vector<BlobParam> params;
};
// The groups, parameter names and shapes a blob holds, in order, without loading any value:
// what a reader needs to tell which model, and which policy heads, a snapshot is for. Throws
// SerializationError when the bytes are not a parameter blob of this version (checksum, magic,
// version, a truncated group or parameter, trailing bytes).
std::vector<BlobGroup> blob_contents(std::span<const std::uint8_t> blob);
// Whether the bytes start with a parameter blob's magic (a file format that may hold either a
// bare blob or something else tells them apart with it; nothing else is checked).
bool starts_like_blob(std::span<const std::uint8_t> bytes);

}  // namespace indrive::nn
