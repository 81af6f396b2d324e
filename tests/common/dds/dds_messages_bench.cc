// Throughput of the per-message work around the wire: frame compression, decompression,
// checksums and validation, on realistic segmentation chunks (64 x 128 x 128 class ids) and a
// 10 MB snapshot. Prints one line per figure.
#include <chrono>
#include <cstdio>

#include "indrive/dds/messages.h"
#include "synthetic_traffic.h"

namespace {

template <typename F>
double seconds_per_call(int calls, F&& work) {
  const auto start = std::chrono::steady_clock::now();
  for (int i = 0; i < calls; ++i) work(i);
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count() / calls;
}

}  // namespace

int main() {
  using namespace indrive;
  constexpr int kCalls = 200;
  const auto frames = testing::synthetic_frames(5, 64, 128, 128);
  const double mb = frames.size() / 1e6;

  for (int level : {1, 3}) {
    std::size_t compressed_size = 0;
    const double compress_s = seconds_per_call(
        kCalls, [&](int) { compressed_size = dds::compress_frames(frames, level).size(); });
    std::printf("zstd level %d compress  : %8.1f MB/s of frames, ratio %.1f\n", level,
                mb / compress_s, static_cast<double>(frames.size()) / compressed_size);
  }
  const auto compressed = dds::compress_frames(frames);
  const double decompress_s = seconds_per_call(
      kCalls, [&](int) { (void)dds::decompress_frames(compressed, frames.size()).size(); });
  std::printf("zstd decompress        : %8.1f MB/s of frames\n", mb / decompress_s);

  const auto chunk = testing::make_synthetic_chunk("bench", 0, 5);
  const double validate_s =
      seconds_per_call(kCalls * 10, [&](int) { (void)dds::validate(chunk, "bench"); });
  std::printf("validate chunk         : %8.1f us per chunk (%zu bytes compressed)\n",
              validate_s * 1e6, chunk.frames_zstd().size());

  const auto snapshot = testing::make_synthetic_snapshot("bench", 1, 10 << 20);
  const double checksum_s =
      seconds_per_call(20, [&](int) { (void)dds::compute_checksum(snapshot); });
  std::printf("checksum 10 MB snapshot: %8.1f ms (%.0f MB/s)\n", checksum_s * 1e3,
              10.0 * 1.048576 / checksum_s);
  return 0;
}
