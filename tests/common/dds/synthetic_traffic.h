// Deterministic synthetic wire traffic for DDS tests: trajectory chunks whose frames look like
// semantic-segmentation images (sky, buildings, road with lane marks, a moving vehicle), and
// policy snapshots with incompressible parameters. A receiver regenerates what it expects from
// the same ids and compares byte for byte.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "indrive/dds/messages.h"

namespace indrive::testing {

// Renders one class-id frame for (episode, step). out is (height, width) uint8.
void render_synthetic_frame(std::uint64_t episode, std::uint64_t step, int height, int width,
                            std::uint8_t* out);

// The frames of chunk `chunk_seq`: (num_steps, height, width) uint8. Frames repeat every 24
// chunks (rendered once and cached) to keep a thousand chunks cheap to generate and check.
std::vector<std::uint8_t> synthetic_frames(std::uint64_t chunk_seq, int num_steps, int height,
                                           int width);

// A sealed chunk (compressed frames, actions, flags, events; checksum set) for chunk_seq.
// Episodes are four chunks long, so flags mark first/last/terminal steps realistically.
msg::TrajectoryChunk make_synthetic_chunk(const std::string& run_id, std::uint32_t actor_id,
                                          std::uint64_t chunk_seq, int num_steps = 64,
                                          int height = 128, int width = 128);

// A sealed snapshot whose params blob holds `size_bytes` pseudo-random bytes from `version`.
msg::PolicySnapshot make_synthetic_snapshot(const std::string& run_id, std::uint64_t version,
                                            std::size_t size_bytes);

// Checks that `chunk` is exactly what make_synthetic_chunk produced for its chunk_seq (frames
// decompressed and compared); returns "" when it is, else what differs.
std::string compare_with_synthetic(const msg::TrajectoryChunk& chunk);

// Same for a snapshot of make_synthetic_snapshot.
std::string compare_with_synthetic(const msg::PolicySnapshot& snapshot);

}  // namespace indrive::testing
