#include "indrive/actor/episode_video.h"

#include <algorithm>
#include <cctype>
#include <cstdio>

#include "indrive/envserver/camera.h"

namespace indrive::actor {

std::filesystem::path episode_video_path(const std::filesystem::path& videos_dir,
                                         const EpisodeSpec& spec) {
  const std::string town = town_file_label(spec.town);
  return videos_dir / ("eval-" + town + "-" + spec.route + "-" + std::to_string(spec.density) +
                       "-" + std::to_string(spec.episode) + ".mp4");
}

EpisodeVideo::EpisodeVideo(const std::filesystem::path& path, const env::Env& env,
                           const EpisodeSpec& spec, int budget)
    : path_(path), bev_(env::BevConfig{}, env.scene()), spec_(spec), budget_(budget) {
  if (env.route() != nullptr) {
    for (const env::Waypoint& w : env.route()->waypoints()) route_.push_back(w.position);
    route_length_m_ = env.route()->length_m();
  }
}

void EpisodeVideo::add(const env::Env& env, const env::StepResult& result) {
  const std::uint32_t events = result.events;
  const cv::Mat camera = env::colorize(result.observation);
  const cv::Mat bev = bev_.render(env.ego_box(), env.traffic_boxes(),
                                  {.route = route_, .alert = env::is_failure(events)});
  char line[96];
  std::vector<std::string> lines;
  lines.push_back(spec_.town + " " + spec_.route + " d" + std::to_string(spec_.density) + " ep" +
                  std::to_string(spec_.episode));
  std::snprintf(line, sizeof(line), "step %d / %d", result.step, budget_);
  lines.emplace_back(line);
  std::snprintf(line, sizeof(line), "speed %.1f m/s", result.ego.speed_mps);
  lines.emplace_back(line);
  const double progress =
      route_length_m_ > 0.0 ? 100.0 * result.route_progress_m / route_length_m_ : 0.0;
  std::snprintf(line, sizeof(line), "route %.0f%% (%.0f m)", progress, result.route_progress_m);
  lines.emplace_back(line);
  cv::Mat frame = env::compose_frame(camera, bev, lines, 384);
  if (events != 0) {
    // Over the camera half only, so the bird's-eye view stays whole.
    cv::Mat camera_part = frame(cv::Rect(0, 0, std::min(frame.cols, frame.rows), frame.rows));
    env::draw_banner(camera_part, env::event_names(events),
                     env::is_failure(events) ? cv::Scalar(200, 30, 30) : cv::Scalar(30, 150, 60));
  }
  if (!writer_) writer_ = std::make_unique<env::VideoWriter>(path_, frame.size(), 10.0);
  writer_->write(frame);
  last_ = frame;
}

void EpisodeVideo::finish(std::uint32_t final_events, bool budget_ran_out) {
  if (!writer_) return;
  if (budget_ran_out) {
    cv::Mat camera_part = last_(cv::Rect(0, 0, std::min(last_.cols, last_.rows), last_.rows));
    env::draw_banner(camera_part, env::event_names(final_events));
  }
  for (int i = 0; i < kEventHoldFrames; ++i) writer_->write(last_);
  writer_->close();
}

}  // namespace indrive::actor
