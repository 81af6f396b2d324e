#include "indrive/basics/checksum.h"

#include <gtest/gtest.h>

#include <string_view>
#include <vector>

namespace indrive {
namespace {

TEST(Crc32, MatchesTheStandardCheckValue) {
  // The CRC-32 check value of "123456789" is 0xCBF43926 for this polynomial.
  const std::string_view text = "123456789";
  EXPECT_EQ(crc32(text.data(), text.size()), 0xCBF43926u);
  EXPECT_EQ(crc32(nullptr, 0), 0u);
}

TEST(Crc32, ContinuesAcrossPiecesAndDetectsAFlippedBit) {
  std::vector<std::uint8_t> bytes(100000);
  for (std::size_t i = 0; i < bytes.size(); ++i) bytes[i] = static_cast<std::uint8_t>(i * 31);
  const std::uint32_t whole = crc32(bytes);
  const std::uint32_t first = crc32(std::span(bytes).first(40000));
  EXPECT_EQ(crc32(std::span(bytes).subspan(40000), first), whole);
  bytes[77777] ^= 0x10;
  EXPECT_NE(crc32(bytes), whole);
}

}  // namespace
}  // namespace indrive
