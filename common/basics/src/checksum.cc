#include "indrive/basics/checksum.h"

#include <zlib.h>

#include <algorithm>
#include <limits>

namespace indrive {

std::uint32_t crc32(const void* data, std::size_t size, std::uint32_t seed) {
  // zlib takes lengths as uInt; feed very large buffers in pieces.
  const auto* bytes = static_cast<const Bytef*>(data);
  uLong crc = seed;
  while (size > 0) {
    const auto piece =
        static_cast<uInt>(std::min<std::size_t>(size, std::numeric_limits<uInt>::max() / 2));
    crc = ::crc32(crc, bytes, piece);
    bytes += piece;
    size -= piece;
  }
  return static_cast<std::uint32_t>(crc);
}

std::uint32_t crc32(std::span<const std::uint8_t> bytes, std::uint32_t seed) {
  return crc32(bytes.data(), bytes.size(), seed);
}

}  // namespace indrive
