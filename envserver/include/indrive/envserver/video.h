// MP4 writing for episode videos, and the side-by-side frame layout (camera | bird's-eye view,
// with a few lines of text on top).
//
//   VideoWriter video("runs/x/videos/ep0.mp4", cv::Size(512, 256), 10.0);
//   const std::string lines[] = {"step 12", "speed 4.9 m/s"};
//   video.write(compose_frame(colorize(ids), bev.render(ego, vehicles), lines));
//   video.close();   // or let the destructor finish the file
#pragma once

#include <filesystem>
#include <opencv2/core.hpp>
#include <opencv2/videoio.hpp>
#include <span>
#include <stdexcept>
#include <string>

namespace indrive::env {

// The video file cannot be opened or written.
class VideoError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Writes RGB frames of one fixed size into an MP4 file (OpenCV's FFmpeg backend, 'mp4v').
class VideoWriter {
 public:
  // Opens the file (parent folders are created); throws VideoError if OpenCV cannot open an
  // MP4 writer there (no FFmpeg support, unwritable folder, bad size or rate).
  VideoWriter(const std::filesystem::path& path, cv::Size frame_size, double fps = 10.0);
  ~VideoWriter();
  VideoWriter(const VideoWriter&) = delete;
  VideoWriter& operator=(const VideoWriter&) = delete;

  // Appends one frame: CV_8UC3 (height, width, 3) in RGB order, of the size given at
  // construction; throws VideoError otherwise or after close().
  void write(const cv::Mat& rgb);
  // Finishes the file; further writes throw. Safe to call twice.
  void close();

  int frames_written() const { return frames_written_; }
  const std::filesystem::path& path() const { return path_; }

 private:
  std::filesystem::path path_;
  cv::Size frame_size_;
  cv::VideoWriter writer_;
  cv::Mat bgr_;  // scratch for the channel swap
  int frames_written_ = 0;
  bool open_ = false;
};

// Lays out one video frame: the camera image scaled up (nearest neighbour, so class pixels
// stay crisp) to height_px on the left, the bird's-eye view scaled to height_px on the right,
// and text_lines written over the top-left corner. camera_rgb is CV_8UC3 (h, w, 3) and
// bev_rgb CV_8UC3 (b, b, 3), both RGB; the result is CV_8UC3 (height_px, W, 3), RGB, where
// W = height_px * w / h + height_px rounded to even for the codec.
cv::Mat compose_frame(const cv::Mat& camera_rgb, const cv::Mat& bev_rgb,
                      std::span<const std::string> text_lines, int height_px = 256);

// Draws `text` in large white letters on a filled band across the bottom of `frame` (CV_8UC3,
// RGB), in the colour `band_rgb`: the event overlay of evaluation videos, so an event that
// fires stands out for the frames it is shown on. Throws VideoError for an empty or non-RGB frame.
void draw_banner(cv::Mat& frame, const std::string& text,
                 const cv::Scalar& band_rgb = cv::Scalar(200, 30, 30));

}  // namespace indrive::env
