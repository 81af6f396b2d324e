// Serialization of named parameter groups to a byte blob, the format of DDS policy snapshots and
// checkpoints.
//
// Layout (little-endian): magic "INNP", u32 version, u32 group count; per group: name, u32
// parameter count; per parameter: name, u32 rank, i64 dims[rank], f32 data[numel]; then the
// CRC-32 of every preceding byte. Names are u32 length + bytes.
#pragma once

#include <cstdint>
#include <functional>
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

// Which parameters a blob holds: keep(group name, parameter name). A blob written with a filter
// holds, per group, only the parameters it keeps, in the group's order; loading it with the same
// filter sets those and leaves the others as they are (e.g. a policy snapshot without the
// world model's decoder, which acting never runs).
using ParamFilter = std::function<bool(const std::string& group, const std::string& param)>;

// Serializes the groups (names, shapes, values) into one blob with a trailing checksum.
std::vector<std::uint8_t> save_params(std::span<const ParamGroup* const> groups);
// Serializes the parameters of the groups that `keep` keeps.
std::vector<std::uint8_t> save_params(std::span<const ParamGroup* const> groups,
                                      const ParamFilter& keep);
// Serializes one group.
std::vector<std::uint8_t> save_params(const ParamGroup& group);
// Loads values into the groups; the blob must hold exactly these groups with the same parameter
// names and shapes in the same order. Throws SerializationError otherwise; the groups are left
// unchanged when loading fails.
void load_params(std::span<const std::uint8_t> blob, std::span<ParamGroup* const> groups);
// Loads a blob written with save_params(groups, keep): it must hold exactly the kept parameters
// of each group, in order; the parameters `keep` leaves out are not touched.
void load_params(std::span<const std::uint8_t> blob, std::span<ParamGroup* const> groups,
                 const ParamFilter& keep);
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
// The blob of the parameters that `keep` keeps of another blob (same groups, same order, values
// copied bit for bit); throws SerializationError as blob_contents does.
std::vector<std::uint8_t> filter_blob(std::span<const std::uint8_t> blob, const ParamFilter& keep);
// Whether the bytes start with a parameter blob's magic (a file format that may hold either a
// bare blob or something else tells them apart with it; nothing else is checked).
bool starts_like_blob(std::span<const std::uint8_t> bytes);

}  // namespace indrive::nn
