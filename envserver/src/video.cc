// MP4 writing through OpenCV's FFmpeg backend, and the side-by-side frame layout.
#include "indrive/envserver/video.h"

#include <algorithm>
#include <opencv2/imgproc.hpp>
#include <system_error>

#include "indrive/basics/log.h"

namespace indrive::env {

VideoWriter::VideoWriter(const std::filesystem::path& path, cv::Size frame_size, double fps)
    : path_(path), frame_size_(frame_size) {
  if (frame_size.width < 2 || frame_size.height < 2 || frame_size.width % 2 != 0 ||
      frame_size.height % 2 != 0) {
    throw VideoError("video " + path.string() + ": frame size " + std::to_string(frame_size.width) +
                     "x" + std::to_string(frame_size.height) +
                     " is not usable; the codec needs even sizes of at least 2 pixels");
  }
  if (!(fps > 0.0 && fps <= 1000.0)) {
    throw VideoError("video " + path.string() + ": frame rate " + std::to_string(fps) +
                     " is out of range; use (0, 1000] frames per second");
  }
  if (path.has_parent_path()) {
    std::error_code error;
    std::filesystem::create_directories(path.parent_path(), error);
    if (error) {
      throw VideoError("video " + path.string() + ": cannot create its folder (" + error.message() +
                       "); choose a writable output folder");
    }
  }
  const int fourcc = cv::VideoWriter::fourcc('m', 'p', '4', 'v');
  if (!writer_.open(path.string(), cv::CAP_FFMPEG, fourcc, fps, frame_size, true)) {
    throw VideoError("video " + path.string() +
                     ": OpenCV could not open an MP4 writer (FFmpeg backend, codec mp4v); check "
                     "that the folder is writable and that OpenCV was built with FFmpeg");
  }
  open_ = true;
}

VideoWriter::~VideoWriter() { close(); }

void VideoWriter::write(const cv::Mat& rgb) {
  if (!open_) throw VideoError("video " + path_.string() + ": write after close()");
  if (rgb.type() != CV_8UC3 || rgb.size() != frame_size_) {
    throw VideoError("video " + path_.string() + ": frame must be CV_8UC3 " +
                     std::to_string(frame_size_.width) + "x" + std::to_string(frame_size_.height) +
                     " (RGB), got type " + std::to_string(rgb.type()) + " of " +
                     std::to_string(rgb.cols) + "x" + std::to_string(rgb.rows));
  }
  cv::cvtColor(rgb, bgr_, cv::COLOR_RGB2BGR);  // OpenCV writers take BGR
  writer_.write(bgr_);
  ++frames_written_;
}

void VideoWriter::close() {
  if (!open_) return;
  writer_.release();
  open_ = false;
  INDRIVE_LOG(kInfo, "video") << "wrote " << frames_written_ << " frames to " << path_.string();
}

cv::Mat compose_frame(const cv::Mat& camera_rgb, const cv::Mat& bev_rgb,
                      std::span<const std::string> text_lines, int height_px) {
  if (camera_rgb.type() != CV_8UC3 || bev_rgb.type() != CV_8UC3 || camera_rgb.empty() ||
      bev_rgb.empty() || height_px < 2) {
    throw VideoError(
        "compose_frame needs non-empty CV_8UC3 camera and bird's-eye images and "
        "height_px >= 2");
  }
  const int camera_width =
      std::max(1, static_cast<int>(std::lround(static_cast<double>(height_px) * camera_rgb.cols /
                                               camera_rgb.rows)));
  const int bev_width = std::max(1, static_cast<int>(std::lround(static_cast<double>(height_px) *
                                                                 bev_rgb.cols / bev_rgb.rows)));
  int width = camera_width + bev_width;
  width += width % 2;  // codecs want even sizes
  const int height = height_px + height_px % 2;

  cv::Mat frame(height, width, CV_8UC3, cv::Scalar(0, 0, 0));
  // Nearest neighbour keeps class pixels crisp when scaling up.
  cv::resize(camera_rgb, frame(cv::Rect(0, 0, camera_width, height_px)),
             cv::Size(camera_width, height_px), 0, 0, cv::INTER_NEAREST);
  cv::resize(bev_rgb, frame(cv::Rect(camera_width, 0, bev_width, height_px)),
             cv::Size(bev_width, height_px), 0, 0, cv::INTER_NEAREST);

  // Text: white on a dark outline so it reads on any class colour.
  const double scale = std::max(0.35, height_px / 640.0);
  const int line_height = static_cast<int>(std::lround(22 * scale / 0.5));
  int y = line_height;
  for (const std::string& line : text_lines) {
    cv::putText(frame, line, cv::Point(6, y), cv::FONT_HERSHEY_SIMPLEX, scale, cv::Scalar(0, 0, 0),
                3, cv::LINE_AA);
    cv::putText(frame, line, cv::Point(6, y), cv::FONT_HERSHEY_SIMPLEX, scale,
                cv::Scalar(255, 255, 255), 1, cv::LINE_AA);
    y += line_height;
  }
  return frame;
}

void draw_banner(cv::Mat& frame, const std::string& text, const cv::Scalar& band_rgb) {
  if (frame.empty() || frame.type() != CV_8UC3) {
    throw VideoError("draw_banner needs a non-empty CV_8UC3 frame");
  }
  // The band takes a fifth of the height; the text is sized to it and kept inside the width.
  const int band_height = std::max(12, frame.rows / 5);
  const cv::Rect band(0, frame.rows - band_height, frame.cols, band_height);
  cv::rectangle(frame, band, band_rgb, cv::FILLED);
  double scale = band_height / 40.0;
  int baseline = 0;
  cv::Size size = cv::getTextSize(text, cv::FONT_HERSHEY_SIMPLEX, scale, 2, &baseline);
  if (size.width > frame.cols - 12) {
    scale *= static_cast<double>(frame.cols - 12) / size.width;
    size = cv::getTextSize(text, cv::FONT_HERSHEY_SIMPLEX, scale, 2, &baseline);
  }
  const cv::Point origin((frame.cols - size.width) / 2, band.y + (band_height + size.height) / 2);
  cv::putText(frame, text, origin, cv::FONT_HERSHEY_SIMPLEX, scale, cv::Scalar(255, 255, 255), 2,
              cv::LINE_AA);
}

}  // namespace indrive::env
