#include "synthetic_traffic.h"

#include <algorithm>
#include <cstring>
#include <map>
#include <mutex>
#include <tuple>

namespace indrive::testing {
namespace {

// Class ids in the CARLA semantic palette order used by the renderer.
constexpr std::uint8_t kSky = 11;
constexpr std::uint8_t kBuilding = 1;
constexpr std::uint8_t kSidewalk = 8;
constexpr std::uint8_t kRoad = 7;
constexpr std::uint8_t kRoadLine = 6;
constexpr std::uint8_t kVehicle = 10;
constexpr std::uint8_t kVegetation = 9;
constexpr int kStepsPerEpisode = 4 * 64;

std::uint64_t mix(std::uint64_t x) {
  // splitmix64 finaliser: decorrelates consecutive ids.
  x += 0x9e3779b97f4a7c15ULL;
  x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ULL;
  x = (x ^ (x >> 27)) * 0x94d049bb133111ebULL;
  return x ^ (x >> 31);
}

}  // namespace

void render_synthetic_frame(std::uint64_t episode, std::uint64_t step, int height, int width,
                            std::uint8_t* out) {
  const std::uint64_t scene = mix(episode);
  const int horizon = height * (35 + static_cast<int>(scene % 10)) / 100;
  const int center = width / 2 + static_cast<int>((mix(episode * 31 + step / 16) % 9)) - 4;
  // Sky and a skyline of buildings whose heights depend on the episode and scroll with steps.
  for (int x = 0; x < width; ++x) {
    const std::uint64_t block = (static_cast<std::uint64_t>(x) + step) / 12;
    const int top = horizon - static_cast<int>(mix(scene ^ block) % (horizon + 1));
    const std::uint8_t solid = mix(scene + block) % 5 == 0 ? kVegetation : kBuilding;
    for (int y = 0; y < horizon; ++y)
      out[static_cast<std::size_t>(y) * width + x] = y >= top ? solid : kSky;
  }
  // Road widening toward the bottom, sidewalks beside it, a dashed centre line.
  for (int y = horizon; y < height; ++y) {
    std::uint8_t* row = out + static_cast<std::size_t>(y) * width;
    const int depth = y - horizon + 1;
    const int half_road = 4 + depth * (width / 2) / std::max(1, height - horizon);
    const int half_walk = half_road + 2 + depth / 6;
    std::memset(row, kVegetation, width);
    const int walk_begin = std::clamp(center - half_walk, 0, width);
    const int walk_end = std::clamp(center + half_walk, 0, width);
    std::memset(row + walk_begin, kSidewalk, walk_end - walk_begin);
    const int road_begin = std::clamp(center - half_road, 0, width);
    const int road_end = std::clamp(center + half_road, 0, width);
    std::memset(row + road_begin, kRoad, road_end - road_begin);
    if (((static_cast<std::uint64_t>(y) + 2 * step) / 6) % 2 == 0 && center >= 0 &&
        center < width) {
      row[center] = kRoadLine;
    }
  }
  // A vehicle ahead that approaches and drifts with the step.
  const int car_y = horizon + 4 + static_cast<int>((step * 3 + scene) % (height - horizon - 8));
  const int car_h = 3 + (car_y - horizon) / 5;
  const int car_w = 2 * car_h;
  const int car_x = center + 2 + static_cast<int>(mix(scene + step / 32) % 6);
  for (int y = car_y; y < std::min(height, car_y + car_h); ++y) {
    for (int x = std::max(0, car_x); x < std::min(width, car_x + car_w); ++x) {
      out[static_cast<std::size_t>(y) * width + x] = kVehicle;
    }
  }
}

namespace {

// Rendered and compressed frames of one clip, shared by every chunk that shows it.
struct Clip {
  std::vector<std::uint8_t> frames;
  std::vector<std::uint8_t> compressed;
};

// Frames repeat every kDistinctClips chunks, so generating and checking a thousand chunks
// costs a few dozen renders; ids, actions, events and checksums still differ per chunk.
constexpr std::uint64_t kDistinctClips = 24;

const Clip& clip_for(std::uint64_t chunk_seq, int num_steps, int height, int width) {
  static std::mutex mutex;
  static std::map<std::tuple<std::uint64_t, int, int, int>, Clip> cache;
  const auto key = std::make_tuple(chunk_seq % kDistinctClips, num_steps, height, width);
  std::lock_guard<std::mutex> lock(mutex);
  auto it = cache.find(key);
  if (it == cache.end()) {
    const std::uint64_t seq = std::get<0>(key);
    const std::uint64_t episode = seq * num_steps / kStepsPerEpisode;
    const std::uint64_t first_step = seq * num_steps % kStepsPerEpisode;
    const std::size_t frame_size = static_cast<std::size_t>(height) * width;
    Clip clip;
    clip.frames.resize(frame_size * num_steps);
    for (int t = 0; t < num_steps; ++t) {
      render_synthetic_frame(episode, first_step + t, height, width,
                             clip.frames.data() + t * frame_size);
    }
    clip.compressed = dds::compress_frames(clip.frames);
    it = cache.emplace(key, std::move(clip)).first;
  }
  return it->second;
}

}  // namespace

std::vector<std::uint8_t> synthetic_frames(std::uint64_t chunk_seq, int num_steps, int height,
                                           int width) {
  return clip_for(chunk_seq, num_steps, height, width).frames;
}

namespace {

// Every field of a synthetic chunk except the frames and the checksum.
msg::TrajectoryChunk synthetic_chunk_without_frames(const std::string& run_id,
                                                    std::uint32_t actor_id, std::uint64_t chunk_seq,
                                                    int num_steps, int height, int width) {
  msg::TrajectoryChunk chunk;
  chunk.run_id(run_id);
  chunk.actor_id(actor_id);
  chunk.chunk_seq(chunk_seq);
  chunk.episode_id(chunk_seq * num_steps / kStepsPerEpisode);
  chunk.first_step(chunk_seq * num_steps % kStepsPerEpisode);
  chunk.num_steps(num_steps);
  chunk.image_height(static_cast<std::uint16_t>(height));
  chunk.image_width(static_cast<std::uint16_t>(width));
  chunk.policy_version(1 + chunk_seq / 100);
  chunk.phase(msg::PHASE_PRETRAIN);
  std::vector<std::uint8_t> actions(num_steps), flags(num_steps);
  std::vector<std::uint16_t> events(num_steps);
  for (int t = 0; t < num_steps; ++t) {
    const std::uint64_t step = chunk.first_step() + t;
    const std::uint64_t noise = mix(chunk_seq * 131 + t);
    actions[t] = static_cast<std::uint8_t>(noise % 9);
    events[t] = static_cast<std::uint16_t>(noise % 97 == 0 ? (1u << (noise % 5)) : 0u);
    if (step == 0) flags[t] |= msg::STEP_IS_FIRST;
    if (step + 1 == kStepsPerEpisode) flags[t] |= msg::STEP_IS_LAST | msg::STEP_IS_TERMINAL;
  }
  chunk.actions(std::move(actions));
  chunk.flags(std::move(flags));
  chunk.events(std::move(events));
  return chunk;
}

}  // namespace

msg::TrajectoryChunk make_synthetic_chunk(const std::string& run_id, std::uint32_t actor_id,
                                          std::uint64_t chunk_seq, int num_steps, int height,
                                          int width) {
  msg::TrajectoryChunk chunk =
      synthetic_chunk_without_frames(run_id, actor_id, chunk_seq, num_steps, height, width);
  chunk.frames_zstd(clip_for(chunk_seq, num_steps, height, width).compressed);
  dds::seal(chunk);
  return chunk;
}

msg::PolicySnapshot make_synthetic_snapshot(const std::string& run_id, std::uint64_t version,
                                            std::size_t size_bytes) {
  msg::PolicySnapshot snapshot;
  snapshot.run_id(run_id);
  snapshot.version(version);
  snapshot.preset("small");
  snapshot.architecture("image=128 cnn_depth=32 deter=512 units=512 stoch=32x32");
  snapshot.heads(msg::HEAD_ENCODER | msg::HEAD_RSSM | msg::HEAD_EXPLORATION_ACTOR);
  snapshot.phase(msg::PHASE_PRETRAIN);
  snapshot.env_steps(version * 1000);
  snapshot.updates(version * 10);
  std::vector<std::uint8_t> params(size_bytes);
  std::uint64_t state = mix(version);
  for (std::size_t i = 0; i < size_bytes; i += 8) {
    state = mix(state);
    std::memcpy(params.data() + i, &state, std::min<std::size_t>(8, size_bytes - i));
  }
  snapshot.params(std::move(params));
  dds::seal(snapshot);
  return snapshot;
}

std::string compare_with_synthetic(const msg::TrajectoryChunk& chunk) {
  const msg::TrajectoryChunk expected =
      synthetic_chunk_without_frames(chunk.run_id(), chunk.actor_id(), chunk.chunk_seq(),
                                     chunk.num_steps(), chunk.image_height(), chunk.image_width());
  if (dds::decompress_frames(chunk) !=
      clip_for(chunk.chunk_seq(), chunk.num_steps(), chunk.image_height(), chunk.image_width())
          .frames) {
    return "frames differ";
  }
  if (chunk.actions() != expected.actions()) return "actions differ";
  if (chunk.flags() != expected.flags()) return "flags differ";
  if (chunk.events() != expected.events()) return "events differ";
  if (chunk.episode_id() != expected.episode_id() || chunk.first_step() != expected.first_step()) {
    return "episode or step index differ";
  }
  return "";
}

std::string compare_with_synthetic(const msg::PolicySnapshot& snapshot) {
  const msg::PolicySnapshot expected =
      make_synthetic_snapshot(snapshot.run_id(), snapshot.version(), snapshot.params().size());
  if (snapshot.params() != expected.params()) return "params differ";
  if (snapshot.checksum() != expected.checksum()) return "checksum differs";
  return "";
}

}  // namespace indrive::testing
