// Render benchmark: milliseconds per frame of the semantic camera on a synthetic town (grid of
// two-lane roads, ~240 buildings) with 20 moving vehicles, at 128x128, 64x64 and 32x32, plus
// the bird's-eye view; optionally saves a few composed frames as PNG to look at.
//
//   camera_bench [--frames N] [--png-dir DIR] [--video FILE.mp4]
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <random>
#include <string>
#include <vector>

#include "camera_scenes.h"
#include "indrive/envserver/bev.h"
#include "indrive/envserver/camera.h"
#include "indrive/envserver/video.h"

namespace {

using Clock = std::chrono::steady_clock;
using indrive::env::Box;
using indrive::env::Pose2;

constexpr double kPi = 3.14159265358979323846;
constexpr double kBlockM = 80.0;

// A vehicle driving along one road of the grid, in its right lane.
struct Mover {
  bool along_x;
  double road;       // y of an x-road or x of a y-road
  double position;   // coordinate along the road
  double direction;  // +1 or -1
  double speed_mps;
};

Box box_of(const Mover& m) {
  const double lane = -1.75 * m.direction;  // right-hand traffic
  if (m.along_x)
    return indrive::env::testing::car_at(m.position, m.road + lane, m.direction > 0 ? 0.0 : kPi);
  return indrive::env::testing::car_at(m.road - lane, m.position,
                                       m.direction > 0 ? kPi / 2 : -kPi / 2);
}

double percentile(std::vector<double> v, double q) {
  std::sort(v.begin(), v.end());
  return v[static_cast<std::size_t>(q * (v.size() - 1))];
}

}  // namespace

int main(int argc, char** argv) {
  int frames = 3000;
  std::string png_dir, video_path;
  for (int i = 1; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--frames") && i + 1 < argc)
      frames = std::atoi(argv[++i]);
    else if (!std::strcmp(argv[i], "--png-dir") && i + 1 < argc)
      png_dir = argv[++i];
    else if (!std::strcmp(argv[i], "--video") && i + 1 < argc)
      video_path = argv[++i];
    else {
      std::fprintf(stderr, "usage: %s [--frames N] [--png-dir DIR] [--video FILE.mp4]\n", argv[0]);
      return 2;
    }
  }

  const auto scene = indrive::env::testing::grid_town(5, 4, kBlockM);
  const auto t0 = Clock::now();
  auto cache = std::make_shared<const indrive::env::SceneCache>(scene);
  const double build_ms = std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
  std::printf(
      "scene: %zu ground polygons, %zu lines, %zu boxes; cache %dx%d cells at %.2f m, "
      "%d line levels, built in %.1f ms\n",
      scene.ground.size(), scene.lines.size(), scene.boxes.size(), cache->ground_map().cols,
      cache->ground_map().rows, cache->resolution_m(), cache->num_levels(), build_ms);

  // Ego drives east along the road y = 80 (right lane), weaving a little; 20 vehicles on the
  // roads around it, all moving.
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  std::vector<Mover> movers;
  for (int k = 0; k < 20; ++k) {
    Mover m;
    m.along_x = k % 2 == 0;
    m.road = kBlockM *
             (m.along_x ? 1 + static_cast<int>(unit(rng) * 2) : static_cast<int>(unit(rng) * 6));
    m.position = m.along_x ? 20.0 + 360.0 * unit(rng) : 10.0 + 300.0 * unit(rng);
    m.direction = unit(rng) < 0.5 ? -1.0 : 1.0;
    m.speed_mps = 3.0 + 7.0 * unit(rng);
    movers.push_back(m);
  }
  auto ego_at = [&](int frame) {
    const double t = frame * 0.1;
    const double x = 10.0 + std::fmod(5.0 * t, 380.0);
    return Pose2{x, kBlockM - 1.75 + 0.6 * std::sin(0.3 * t), 0.08 * std::cos(0.3 * t)};
  };
  auto vehicles_at = [&](int frame, std::vector<Box>& out) {
    out.clear();
    for (const Mover& m : movers) {
      Mover moved = m;
      const double span = m.along_x ? 400.0 : 320.0;
      moved.position =
          std::fmod(m.position + m.direction * m.speed_mps * frame * 0.1 + 10 * span, span);
      out.push_back(box_of(moved));
    }
  };

  std::vector<Box> vehicles;
  std::printf("%-10s %10s %10s %10s %12s\n", "view", "mean_ms", "p50_ms", "p99_ms", "frames/s");
  for (const int size : {128, 64, 32}) {
    indrive::env::SemanticCamera camera(indrive::env::CameraConfig{.width = size, .height = size},
                                        cache);
    cv::Mat ids;
    std::vector<double> times;
    times.reserve(frames);
    std::uint64_t checksum = 0;  // keeps the work observable
    for (int f = 0; f < frames; ++f) {
      vehicles_at(f, vehicles);
      const auto start = Clock::now();
      camera.render(ego_at(f), vehicles, ids);
      times.push_back(std::chrono::duration<double, std::milli>(Clock::now() - start).count());
      checksum += ids.at<std::uint8_t>(size - 1, size / 2);
    }
    double total = 0.0;
    for (const double t : times) total += t;
    std::printf("camera%-4d %10.4f %10.4f %10.4f %12.0f   (checksum %llu)\n", size, total / frames,
                percentile(times, 0.5), percentile(times, 0.99), 1000.0 * frames / total,
                static_cast<unsigned long long>(checksum));
  }
  {
    // The same drive without any boxes: the ground pass alone, to show the split.
    indrive::env::StaticScene flat = scene;
    flat.boxes.clear();
    auto flat_cache = std::make_shared<const indrive::env::SceneCache>(flat);
    indrive::env::SemanticCamera camera(indrive::env::CameraConfig{}, flat_cache);
    cv::Mat ids;
    const auto start = Clock::now();
    for (int f = 0; f < frames; ++f) camera.render(ego_at(f), {}, ids);
    const double total = std::chrono::duration<double, std::milli>(Clock::now() - start).count();
    std::printf("ground128  %10.4f %10s %10s %12.0f   (no boxes, no vehicles)\n", total / frames,
                "-", "-", 1000.0 * frames / total);
  }
  {
    indrive::env::BirdsEyeView bev(indrive::env::BevConfig{}, cache);
    const int bev_frames = std::max(1, frames / 10);
    std::vector<double> times;
    for (int f = 0; f < bev_frames; ++f) {
      vehicles_at(f, vehicles);
      const Pose2 ego = ego_at(f);
      const auto start = Clock::now();
      const cv::Mat rgb = bev.render(Box{indrive::env::SemanticClass::kVehicle, ego}, vehicles);
      times.push_back(std::chrono::duration<double, std::milli>(Clock::now() - start).count());
    }
    double total = 0.0;
    for (const double t : times) total += t;
    std::printf("bev256    %10.4f %10.4f %10.4f %12.0f\n", total / bev_frames,
                percentile(times, 0.5), percentile(times, 0.99), 1000.0 * bev_frames / total);
  }

  if (!png_dir.empty()) {
    std::filesystem::create_directories(png_dir);
    indrive::env::SemanticCamera camera(indrive::env::CameraConfig{}, cache);
    indrive::env::BirdsEyeView bev(indrive::env::BevConfig{}, cache);
    for (const int f : {30, 150, 420, 700}) {
      vehicles_at(f, vehicles);
      const Pose2 ego = ego_at(f);
      const std::vector<Eigen::Vector2d> route = {{ego.x_m, kBlockM - 1.75},
                                                  {ego.x_m + 100.0, kBlockM - 1.75}};
      const cv::Mat rgb = indrive::env::compose_frame(
          indrive::env::colorize(camera.render(ego, vehicles)),
          bev.render(Box{indrive::env::SemanticClass::kVehicle, ego}, vehicles, {.route = route}),
          std::vector<std::string>{"frame " + std::to_string(f)}, 512);
      cv::Mat bgr;
      cv::cvtColor(rgb, bgr, cv::COLOR_RGB2BGR);
      const std::string path = png_dir + "/camera_bev_" + std::to_string(f) + ".png";
      cv::imwrite(path, bgr);
      std::printf("wrote %s\n", path.c_str());
    }
  }
  if (!png_dir.empty()) {
    // The preset sizes side by side, scaled up, to check that lines survive at 64 and 32.
    const Pose2 ego = ego_at(420);
    vehicles_at(420, vehicles);
    std::vector<cv::Mat> panels;
    for (const int size : {128, 64, 32}) {
      indrive::env::SemanticCamera camera(indrive::env::CameraConfig{.width = size, .height = size},
                                          cache);
      cv::Mat big;
      cv::resize(indrive::env::colorize(camera.render(ego, vehicles)), big, cv::Size(384, 384), 0,
                 0, cv::INTER_NEAREST);
      panels.push_back(big);
    }
    cv::Mat row, bgr;
    cv::hconcat(panels, row);
    cv::cvtColor(row, bgr, cv::COLOR_RGB2BGR);
    cv::imwrite(png_dir + "/camera_sizes_128_64_32.png", bgr);
    std::printf("wrote %s/camera_sizes_128_64_32.png\n", png_dir.c_str());
  }
  if (!video_path.empty()) {
    // 20 s of driving at 10 Hz, camera | bird's-eye view, as the episode videos will look.
    indrive::env::SemanticCamera camera(indrive::env::CameraConfig{}, cache);
    indrive::env::BirdsEyeView bev(indrive::env::BevConfig{}, cache);
    indrive::env::VideoWriter video(video_path, cv::Size(512, 256), 10.0);
    for (int f = 0; f < 200; ++f) {
      vehicles_at(f, vehicles);
      const Pose2 ego = ego_at(f);
      video.write(indrive::env::compose_frame(
          indrive::env::colorize(camera.render(ego, vehicles)),
          bev.render(Box{indrive::env::SemanticClass::kVehicle, ego}, vehicles),
          std::vector<std::string>{"step " + std::to_string(f)}, 256));
    }
    video.close();
    std::printf("wrote %s (%d frames)\n", video_path.c_str(), video.frames_written());
  }
  return 0;
}
