// Class ids to the CARLA palette, and the checks of the camera and bird's-eye view configs.
#include <cmath>
#include <sstream>

#include "indrive/basics/check.h"
#include "indrive/envserver/bev.h"
#include "indrive/envserver/camera.h"

namespace indrive::env {
namespace {

[[noreturn]] void bad_field(const char* owner, const char* field, double value, const char* want) {
  std::ostringstream message;
  message << owner << "." << field << " = " << value << " is out of range: " << want;
  throw CameraError(message.str());
}

}  // namespace

void validate(const CameraConfig& config) {
  if (config.width < 1 || config.width > 4096)
    bad_field("camera", "width", config.width, "use 1..4096 pixels (the preset's image size)");
  if (config.height < 1 || config.height > 4096)
    bad_field("camera", "height", config.height, "use 1..4096 pixels (the preset's image size)");
  if (!(config.hfov_deg > 1.0 && config.hfov_deg < 170.0))
    bad_field("camera", "hfov_deg", config.hfov_deg, "use a field of view in (1, 170) degrees");
  if (!std::isfinite(config.forward_m))
    bad_field("camera", "forward_m", config.forward_m, "must be a finite distance in metres");
  if (!(config.height_m > 0.0 && config.height_m < 100.0))
    bad_field("camera", "height_m", config.height_m,
              "the camera must be above the ground (0, 100) m");
  if (!(config.pitch_deg > -60.0 && config.pitch_deg < 60.0))
    bad_field("camera", "pitch_deg", config.pitch_deg, "use a pitch in (-60, 60) degrees");
  if (!(config.near_m > 0.0 && config.near_m < config.far_m))
    bad_field("camera", "near_m", config.near_m, "use 0 < near_m < far_m");
  if (!(config.far_m < 1e5))
    bad_field("camera", "far_m", config.far_m, "use a far plane under 100 km");
}

void validate(const BevConfig& config) {
  if (config.size_px < 8 || config.size_px > 4096)
    bad_field("bev", "size_px", config.size_px, "use 8..4096 pixels");
  if (!(config.extent_m > 1.0 && config.extent_m < 10000.0))
    bad_field("bev", "extent_m", config.extent_m, "use (1, 10000) metres");
  if (!(config.ego_row_fraction >= 0.0 && config.ego_row_fraction <= 1.0))
    bad_field("bev", "ego_row_fraction", config.ego_row_fraction, "use a fraction in [0, 1]");
}

void colorize(const cv::Mat& class_ids, cv::Mat& rgb) {
  INDRIVE_CHECK(class_ids.type() == CV_8UC1) << "colorize expects CV_8UC1 class ids";
  rgb.create(class_ids.rows, class_ids.cols, CV_8UC3);
  for (int row = 0; row < class_ids.rows; ++row) {
    const std::uint8_t* in = class_ids.ptr<std::uint8_t>(row);
    std::uint8_t* out = rgb.ptr<std::uint8_t>(row);
    for (int col = 0; col < class_ids.cols; ++col) {
      const int id = in[col] < kNumSemanticClasses ? in[col] : 0;
      out[3 * col + 0] = kPaletteRgb[id][0];
      out[3 * col + 1] = kPaletteRgb[id][1];
      out[3 * col + 2] = kPaletteRgb[id][2];
    }
  }
}

cv::Mat colorize(const cv::Mat& class_ids) {
  cv::Mat rgb;
  colorize(class_ids, rgb);
  return rgb;
}

}  // namespace indrive::env
