// Checksums for data that crosses a boundary (DDS messages, snapshots, checkpoints).
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>

namespace indrive {

// CRC-32 (the zlib/PNG polynomial) of a byte range. `seed` continues an earlier checksum, so
// crc32(b, crc32(a)) == crc32(a followed by b).
std::uint32_t crc32(std::span<const std::uint8_t> bytes, std::uint32_t seed = 0);
std::uint32_t crc32(const void* data, std::size_t size, std::uint32_t seed = 0);

}  // namespace indrive
