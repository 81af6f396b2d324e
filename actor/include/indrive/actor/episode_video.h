// MP4 of one evaluation episode: the camera beside a bird's-eye view with the route, a few text
// lines (cell, step, speed, route progress), and the events in a band while they fire. The
// evaluator and the local evaluation of indrive-train-local record the first
// eval.video_episodes episodes of every cell with it.
//
//   EpisodeVideo video(episode_video_path(run.videos(), spec), env, spec, budget);
//   video.add(env, step);                   // after the reset and after every step
//   video.finish(events, budget_ran_out);   // holds the last frame for a second
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "indrive/actor/eval_protocol.h"
#include "indrive/envserver/bev.h"
#include "indrive/envserver/env.h"
#include "indrive/envserver/video.h"

namespace indrive::actor {

// `<videos_dir>/eval-<town>-<route>-<density>-<episode>.mp4`; a town given as a map path keeps
// only its stem, and characters other than letters, digits, '_' and '-' become '_'.
std::filesystem::path episode_video_path(const std::filesystem::path& videos_dir,
                                         const EpisodeSpec& spec);

class EpisodeVideo {
 public:
  // Frames a fired event stays on screen after the episode ends (1 s at 10 Hz).
  static constexpr int kEventHoldFrames = 10;

  // The file is created at the first add(); `budget` is the episode's step budget (shown).
  EpisodeVideo(const std::filesystem::path& path, const env::Env& env, const EpisodeSpec& spec,
               int budget);

  void add(const env::Env& env, const env::StepResult& result);
  // Ends the video, holding the last frame (with a band naming final_events when the budget ran
  // out) for kEventHoldFrames frames.
  void finish(std::uint32_t final_events, bool budget_ran_out);

 private:
  std::filesystem::path path_;
  env::BirdsEyeView bev_;
  EpisodeSpec spec_;
  int budget_;
  std::vector<Eigen::Vector2d> route_;
  double route_length_m_ = 0.0;
  std::unique_ptr<env::VideoWriter> writer_;
  cv::Mat last_;
};

}  // namespace indrive::actor
