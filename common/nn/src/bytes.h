// Little-endian byte writer and bounds-checked reader for the blob formats of serialize.cc and
// optim.cc (private to common/nn/src).
#pragma once

#include <bit>
#include <cstdint>
#include <cstring>
#include <span>
#include <string>
#include <vector>

#include "indrive/basics/checksum.h"
#include "indrive/nn/serialize.h"

namespace indrive::nn::detail {

static_assert(std::endian::native == std::endian::little, "blob formats assume little-endian");

class ByteWriter {
 public:
  void raw(const void* p, std::size_t n) {
    const auto* b = static_cast<const std::uint8_t*>(p);
    out_.insert(out_.end(), b, b + n);
  }
  void u32(std::uint32_t v) { raw(&v, 4); }
  void i64(std::int64_t v) { raw(&v, 8); }
  void str(const std::string& s) {
    u32(static_cast<std::uint32_t>(s.size()));
    raw(s.data(), s.size());
  }
  void floats(std::span<const float> v) { raw(v.data(), v.size() * sizeof(float)); }
  // Appends the CRC-32 of everything written so far and returns the blob.
  std::vector<std::uint8_t> finish() {
    u32(crc32(out_.data(), out_.size()));
    return std::move(out_);
  }

 private:
  std::vector<std::uint8_t> out_;
};

class ByteReader {
 public:
  // Checks the trailing CRC-32 before anything is read; `what` names the blob in messages.
  ByteReader(std::span<const std::uint8_t> blob, std::string what) : what_(std::move(what)) {
    if (blob.size() < 4)
      throw SerializationError(what_ + ": blob of " + std::to_string(blob.size()) +
                               " bytes is too short to hold a checksum; it is truncated or empty");
    std::uint32_t stored;
    std::memcpy(&stored, blob.data() + blob.size() - 4, 4);
    const std::uint32_t actual = crc32(blob.data(), blob.size() - 4);
    if (stored != actual)
      throw SerializationError(what_ + ": checksum mismatch (stored " + std::to_string(stored) +
                               ", computed " + std::to_string(actual) +
                               "); the blob is corrupt or truncated, re-send or re-save it");
    data_ = blob.first(blob.size() - 4);
  }
  void raw(void* p, std::size_t n) {
    if (pos_ + n > data_.size())
      throw SerializationError(what_ + ": unexpected end of data at byte " + std::to_string(pos_) +
                               " (needed " + std::to_string(n) + " more bytes)");
    std::memcpy(p, data_.data() + pos_, n);
    pos_ += n;
  }
  std::uint32_t u32() {
    std::uint32_t v;
    raw(&v, 4);
    return v;
  }
  std::int64_t i64() {
    std::int64_t v;
    raw(&v, 8);
    return v;
  }
  std::string str() {
    const std::uint32_t n = u32();
    if (n > data_.size() - pos_)
      throw SerializationError(what_ + ": name length " + std::to_string(n) + " at byte " +
                               std::to_string(pos_) + " runs past the end of the blob");
    std::string s(n, '\0');
    raw(s.data(), n);
    return s;
  }
  void floats(std::span<float> v) { raw(v.data(), v.size() * sizeof(float)); }
  // Steps over `n` bytes without reading them.
  void skip(std::uint64_t n) {
    if (n > data_.size() - pos_)
      throw SerializationError(what_ + ": unexpected end of data at byte " + std::to_string(pos_) +
                               " (needed " + std::to_string(n) + " more bytes)");
    pos_ += static_cast<std::size_t>(n);
  }
  bool done() const { return pos_ == data_.size(); }
  const std::string& what() const { return what_; }

 private:
  std::span<const std::uint8_t> data_;
  std::size_t pos_ = 0;
  std::string what_;
};

}  // namespace indrive::nn::detail
