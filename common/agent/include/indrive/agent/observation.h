// Conversion of semantic class-id frames into the network's RGB input.
#pragma once

#include <array>
#include <cstdint>
#include <span>

namespace indrive::agent {

// Number of semantic classes of the camera.
inline constexpr int kNumClasses = 8;

// The camera's palette (CARLA's colours) for class ids 0..7: unlabeled, road, road line,
// sidewalk, vehicle, building, vegetation, sky. Must equal the envserver's palette (tested).
inline constexpr std::array<std::array<std::uint8_t, 3>, kNumClasses> kPaletteRgb = {{
    {0, 0, 0},
    {128, 64, 128},
    {157, 234, 50},
    {244, 35, 232},
    {0, 0, 142},
    {70, 70, 70},
    {107, 142, 35},
    {70, 130, 180},
}};

// Writes the RGB image in [0, 1] of class-id frames. ids is (N, H, W) with values < kNumClasses
// (checked); rgb is (N, H, W, 3) and must have 3 * ids.size() floats.
void class_ids_to_rgb(std::span<const std::uint8_t> ids, std::span<float> rgb);

}  // namespace indrive::agent
