// LinePlot, drawn by PLplot (its cairo memory driver, memcairo) into an RGB buffer that becomes
// the caller's OpenCV image: PLplot lays out the axes, ticks, text and legend, antialiased
// through cairo; this file only decides what goes where (ranges, ticks, smoothing, bands, the
// legend's corner).
#include <plplot.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <iomanip>
#include <limits>
#include <mutex>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <sstream>
#include <stdexcept>

#include "indrive/basics/run_dir.h"
#include "indrive/deploy/plot.h"

namespace indrive::deploy {
namespace {

// Series with fewer points are never smoothed (see LinePlot::set_smoothing).
constexpr std::size_t kMinPointsToSmooth = 50;

// Tableau-like colours, RGB.
constexpr std::array<std::array<int, 3>, 8> kColours = {{{31, 119, 180},
                                                         {255, 127, 14},
                                                         {44, 160, 44},
                                                         {214, 39, 40},
                                                         {148, 103, 189},
                                                         {140, 86, 75},
                                                         {227, 119, 194},
                                                         {127, 127, 127}}};
// PLplot's colour map 0 as this file uses it: fixed slots, then one line, one faint and one band
// colour per series colour.
enum Slot { kWhite = 0, kBlack = 1, kGrid = 2, kSoftText = 3, kFirstSeries = 4 };
int line_slot(std::size_t k) { return kFirstSeries + static_cast<int>(k % kColours.size()); }
int faint_slot(std::size_t k) { return line_slot(k) + static_cast<int>(kColours.size()); }
int band_slot(std::size_t k) { return line_slot(k) + 2 * static_cast<int>(kColours.size()); }

std::string tick_label(double value, double step) {
  // Large values get a k or M suffix scaled by the whole axis step, so one axis never mixes
  // notations ("50k, 100k", not "50000, 1.00e+05").
  const double magnitude = std::max(std::abs(value), std::abs(step));
  double scale = 1.0;
  const char* suffix = "";
  if (magnitude >= 1e6) {
    scale = 1e6;
    suffix = "M";
  } else if (magnitude >= 1e3) {
    scale = 1e3;
    suffix = "k";
  }
  const double scaled_step = step / scale;
  std::ostringstream out;
  if (magnitude > 0 && magnitude < 1e-3) {
    out << std::setprecision(2) << std::scientific << value;
    return out.str();
  }
  const int decimals =
      scaled_step >= 1 ? 0 : static_cast<int>(std::ceil(-std::log10(scaled_step) - 1e-9));
  out << std::fixed << std::setprecision(decimals) << value / scale << suffix;
  return out.str();
}

struct AxisSteps {
  double x = 1.0, y = 1.0;
};
void label_tick(PLINT axis, PLFLT value, char* text, PLINT length, PLPointer data) {
  const auto* steps = static_cast<const AxisSteps*>(data);
  const std::string label = tick_label(value, axis == PL_X_AXIS ? steps->x : steps->y);
  std::snprintf(text, static_cast<std::size_t>(length), "%s", label.c_str());
}

// PLplot keeps its streams in global state: one plot at a time per process.
std::mutex& plplot_mutex() {
  static std::mutex mutex;
  return mutex;
}

// PLplot exits the process when a device cannot be loaded; ask first whether it is there.
void require_memcairo() {
  static const bool present = [] {
    std::array<const char*, 128> menus{}, names{};
    const char** menu_list = menus.data();
    const char** name_list = names.data();
    int count = static_cast<int>(names.size());
    plgDevs(&menu_list, &name_list, &count);
    return std::any_of(name_list, name_list + count,
                       [](const char* name) { return name && std::string(name) == "memcairo"; });
  }();
  if (!present) {
    throw IoError(
        "PNG plots need PLplot's cairo driver (memcairo), which is not installed: apt-get install "
        "plplot-driver-cairo (deploy/setup.sh installs it)");
  }
}

// One PLplot stream drawing into an RGB buffer; ended (and the buffer final) on destruction.
class MemoryStream {
 public:
  MemoryStream(int width, int height, std::vector<std::uint8_t>& rgb) {
    plmkstrm(&stream_);
    plsdev("memcairo");
    plsmem(width, height, rgb.data());
    plscmap0n(kFirstSeries + 3 * static_cast<int>(kColours.size()));
    plscolbg(255, 255, 255);
    plscol0a(kWhite, 255, 255, 255, 1.0);
    plscol0a(kBlack, 0, 0, 0, 1.0);
    plscol0a(kGrid, 225, 225, 225, 1.0);
    plscol0a(kSoftText, 90, 90, 90, 1.0);
    for (std::size_t k = 0; k < kColours.size(); ++k) {
      const auto [r, g, b] = kColours[k];
      plscol0a(line_slot(k), r, g, b, 1.0);
      plscol0a(faint_slot(k), (r + 2 * 255) / 3, (g + 2 * 255) / 3, (b + 2 * 255) / 3, 1.0);
      plscol0a(band_slot(k), r, g, b, 0.2);
    }
    plinit();
    pladv(0);
  }
  ~MemoryStream() { plend1(); }
  MemoryStream(const MemoryStream&) = delete;
  MemoryStream& operator=(const MemoryStream&) = delete;

 private:
  PLINT stream_ = 0;
};

void draw_polyline(const std::vector<PLFLT>& x, const std::vector<PLFLT>& y, int slot,
                   double width) {
  plcol0(slot);
  plwidth(width);
  plline(static_cast<PLINT>(x.size()), x.data(), y.data());
}

}  // namespace

struct LinePlot::Range {
  double x_min = std::numeric_limits<double>::infinity(), x_max = -x_min;
  double y_min = x_min, y_max = -x_min;
  bool empty() const { return !std::isfinite(x_min); }
};

std::vector<double> nice_ticks(double low, double high, int count) {
  if (!(high > low)) return {low};
  const double raw = (high - low) / std::max(1, count);
  const double power = std::pow(10.0, std::floor(std::log10(raw)));
  double step = power;
  for (const double m : {1.0, 2.0, 5.0, 10.0}) {
    step = m * power;
    if (step >= raw) break;
  }
  std::vector<double> ticks;
  for (double t = std::ceil(low / step) * step; t <= high + step * 1e-9; t += step) {
    ticks.push_back(std::abs(t) < step * 1e-9 ? 0.0 : t);
  }
  return ticks;
}

LinePlot::LinePlot(std::string title, std::string x_label, std::string y_label)
    : title_(std::move(title)), x_label_(std::move(x_label)), y_label_(std::move(y_label)) {}

void LinePlot::add_series(const std::string& name, std::vector<double> x, std::vector<double> y) {
  if (x.size() != y.size()) {
    throw std::invalid_argument("series '" + name + "': x has " + std::to_string(x.size()) +
                                " points, y has " + std::to_string(y.size()));
  }
  series_.push_back({name, std::move(x), std::move(y), {}, {}});
}

void LinePlot::add_series(const std::string& name, std::vector<double> x, std::vector<double> y,
                          std::vector<double> low, std::vector<double> high) {
  if (low.size() != x.size() || high.size() != x.size()) {
    throw std::invalid_argument("series '" + name + "': x has " + std::to_string(x.size()) +
                                " points, its band " + std::to_string(low.size()) + " and " +
                                std::to_string(high.size()));
  }
  add_series(name, std::move(x), std::move(y));
  series_.back().low = std::move(low);
  series_.back().high = std::move(high);
}

cv::Mat LinePlot::render(int width, int height) const {
  Range range;
  for (const auto& s : series_) {
    for (std::size_t i = 0; i < s.x.size(); ++i) {
      if (!std::isfinite(s.x[i]) || !std::isfinite(s.y[i])) continue;
      range.x_min = std::min(range.x_min, s.x[i]);
      range.x_max = std::max(range.x_max, s.x[i]);
      range.y_min = std::min(range.y_min, s.y[i]);
      range.y_max = std::max(range.y_max, s.y[i]);
    }
    for (std::size_t i = 0; i < s.low.size(); ++i) {
      if (!std::isfinite(s.x[i]) || !std::isfinite(s.low[i]) || !std::isfinite(s.high[i])) {
        continue;
      }
      range.y_min = std::min(range.y_min, s.low[i]);
      range.y_max = std::max(range.y_max, s.high[i]);
    }
  }
  if (!range.empty()) {
    if (range.x_max == range.x_min) range.x_max = range.x_min + 1.0;
    if (range.y_max == range.y_min) {
      range.y_max += 0.5 * std::max(1.0, std::abs(range.y_max));
      range.y_min -= 0.5 * std::max(1.0, std::abs(range.y_min));
    }
    const double pad = 0.05 * (range.y_max - range.y_min);
    range.y_min -= pad;
    range.y_max += pad;
  }

  require_memcairo();
  std::vector<std::uint8_t> rgb(static_cast<std::size_t>(width) * height * 3, 255);
  {
    const std::lock_guard lock(plplot_mutex());
    MemoryStream stream(width, height, rgb);
    // The axes' box in pixels from the image's edges: left 80, right 20, top 40, bottom 55.
    plvpor(80.0 / width, 1.0 - 20.0 / width, 55.0 / height, 1.0 - 40.0 / height);
    plschr(0.0, 0.9);
    plcol0(kBlack);
    plmtex("t", 1.2, 0.5, 0.5, title_.c_str());
    if (range.empty()) {
      plwind(0.0, 1.0, 0.0, 1.0);
      plcol0(kSoftText);
      plmtex("t", -8.0, 0.5, 0.5, "no data");
    } else {
      draw_axes(range);
      draw_series(range);
    }
  }
  cv::Mat image(height, width, CV_8UC3, rgb.data());
  cv::Mat bgr;
  cv::cvtColor(image, bgr, cv::COLOR_RGB2BGR);
  return bgr;
}

void LinePlot::draw_axes(const Range& range) const {
  plwind(range.x_min, range.x_max, range.y_min, range.y_max);
  const auto x_ticks = nice_ticks(range.x_min, range.x_max, 6);
  const auto y_ticks = nice_ticks(range.y_min, range.y_max, 6);
  // PLplot keeps the pointer until the label function is cleared at the end of this function.
  AxisSteps steps{x_ticks.size() > 1 ? x_ticks[1] - x_ticks[0] : 1.0,
                  y_ticks.size() > 1 ? y_ticks[1] - y_ticks[0] : 1.0};
  plslabelfunc(label_tick, &steps);
  plwidth(1.0);
  plcol0(kGrid);
  plbox("g", steps.x, 0, "g", steps.y, 0);
  plcol0(kBlack);
  plschr(0.0, 0.8);
  plbox("bcnto", steps.x, 0, "bcntvo", steps.y, 0);
  plschr(0.0, 0.9);
  plmtex("b", 3.0, 0.5, 0.5, x_label_.c_str());
  plcol0(kSoftText);
  plmtex("l", 5.5, 0.5, 0.5, y_label_.c_str());
  plslabelfunc(nullptr, nullptr);
}

void LinePlot::draw_series(const Range& range) const {
  // Bands first, lightly, so that no band hides another series' line.
  for (std::size_t k = 0; k < series_.size(); ++k) {
    const auto& s = series_[k];
    std::vector<PLFLT> x, y;
    for (std::size_t i = 0; i < s.low.size(); ++i) {
      if (!std::isfinite(s.x[i]) || !std::isfinite(s.low[i]) || !std::isfinite(s.high[i])) {
        continue;
      }
      x.push_back(s.x[i]);
      y.push_back(s.high[i]);
    }
    if (x.size() < 2) continue;
    for (std::size_t i = s.low.size(); i-- > 0;) {
      if (!std::isfinite(s.x[i]) || !std::isfinite(s.low[i]) || !std::isfinite(s.high[i])) {
        continue;
      }
      x.push_back(s.x[i]);
      y.push_back(s.low[i]);
    }
    plcol0(band_slot(k));
    plfill(static_cast<PLINT>(x.size()), x.data(), y.data());
  }

  // Series: raw faintly when smoothing, then the (smoothed) line.
  std::array<int, 2> crossings{};  // drawn points in the legend's upper-left / upper-right spot
  for (std::size_t k = 0; k < series_.size(); ++k) {
    const auto& s = series_[k];
    // A short series (a fast run logs few metrics lines) is drawn as it is: an average over
    // a handful of points would lag far behind its values.
    const double weight = s.x.size() >= kMinPointsToSmooth ? smoothing_ : 0.0;
    std::vector<PLFLT> x, raw, smooth;
    double ema = std::numeric_limits<double>::quiet_NaN();
    for (std::size_t i = 0; i < s.x.size(); ++i) {
      if (!std::isfinite(s.x[i]) || !std::isfinite(s.y[i])) continue;
      ema = std::isnan(ema) ? s.y[i] : weight * ema + (1.0 - weight) * s.y[i];
      x.push_back(s.x[i]);
      raw.push_back(s.y[i]);
      smooth.push_back(ema);
    }
    if (weight > 0.0) draw_polyline(x, raw, faint_slot(k), 1.0);
    const auto& line = weight > 0.0 ? smooth : raw;
    draw_polyline(x, line, line_slot(k), 2.0);
    if (x.size() == 1) {
      plcol0(line_slot(k));
      plpoin(1, x.data(), line.data(), 17);
    }
    for (std::size_t i = 0; i < x.size(); ++i) {
      const double u = (x[i] - range.x_min) / (range.x_max - range.x_min);
      const double v = (line[i] - range.y_min) / (range.y_max - range.y_min);
      if (v > 0.65 && u < 0.4) ++crossings[0];
      if (v > 0.65 && u > 0.6) ++crossings[1];
    }
  }

  // The legend goes last, into the upper corner of the axes that the lines cross least.
  const int n = static_cast<int>(series_.size());
  std::vector<PLINT> options(n, PL_LEGEND_LINE), colours(n), text_colours(n, kBlack), styles(n, 1);
  std::vector<PLFLT> widths(n, 2.0);
  std::vector<const char*> names(n);
  for (int k = 0; k < n; ++k) {
    colours[k] = line_slot(static_cast<std::size_t>(k));
    names[k] = series_[k].name.c_str();
  }
  const PLINT corner = crossings[0] < crossings[1] ? PL_POSITION_LEFT : PL_POSITION_RIGHT;
  PLFLT legend_width = 0, legend_height = 0;
  plschr(0.0, 0.8);
  pllegend(&legend_width, &legend_height, PL_LEGEND_BACKGROUND | PL_LEGEND_BOUNDING_BOX,
           PL_POSITION_TOP | corner | PL_POSITION_INSIDE, 0.01, 0.01, 0.06, kWhite, kGrid, 1, 0, 0,
           n, options.data(), 0.8, 0.85, 2.0, 0.0, text_colours.data(), names.data(), nullptr,
           nullptr, nullptr, nullptr, colours.data(), styles.data(), widths.data(), nullptr,
           nullptr, nullptr, nullptr);
}

void LinePlot::save(const std::filesystem::path& path, int width, int height) const {
  const cv::Mat image = render(width, height);
  std::vector<std::uint8_t> png;
  if (!cv::imencode(".png", image, png)) throw IoError("cannot encode plot " + path.string());
  atomic_write(path, png);
}

}  // namespace indrive::deploy
