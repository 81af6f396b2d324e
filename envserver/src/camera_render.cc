// The semantic camera: inverse-perspective ground lookup plus depth-buffered boxes.
//
// Frames: world (x east, y north, z up); ego (forward, left, up) at the footprint centre;
// camera (x right, y down, z along the optical axis) at (forward_m, 0, height_m) in the ego
// frame, pitched down by pitch_deg. Pixel (i, j) covers [i, i+1) x [j, j+1); its centre is
// (i + 0.5, j + 0.5).
//
// Why this design (measured with the camera_bench program): the ground is most of the image, and
// a per-pixel lookup in a top-down map costs a few nanoseconds with no per-polygon work at all,
// so cost does not grow with town size. Drawing ground polygons in perspective each frame
// would need clipping and a culled polygon set per frame, for the same picture.
#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <limits>

#include "camera_geometry.h"
#include "indrive/basics/check.h"
#include "indrive/envserver/camera.h"

namespace indrive::env {
namespace {

constexpr double kPi = 3.14159265358979323846;

// The world-to-camera transform for one ego pose, plus the intrinsics.
struct View {
  double ego_x, ego_y, cos_yaw, sin_yaw;
  double mount_forward, mount_height, cos_pitch, sin_pitch;
  double focal, cx, cy;  // pixels
  double tan_x, tan_y;   // half-extent of the image over the focal length
  double near, far;      // camera depth limits
  int width, height;

  // Camera coordinates of a world point.
  Eigen::Vector3d to_camera(double wx, double wy, double wz) const {
    const double dx = wx - ego_x;
    const double dy = wy - ego_y;
    const double forward = cos_yaw * dx + sin_yaw * dy - mount_forward;
    const double left = -sin_yaw * dx + cos_yaw * dy;
    const double up = wz - mount_height;
    return {-left, -sin_pitch * forward - cos_pitch * up, cos_pitch * forward - sin_pitch * up};
  }
  // World (x, y) of a camera-frame point (the inverse of to_camera, z dropped).
  Eigen::Vector2d to_world_xy(const Eigen::Vector3d& c) const {
    const double forward = cos_pitch * c.z() - sin_pitch * c.y() + mount_forward;
    const double left = -c.x();
    return {ego_x + cos_yaw * forward - sin_yaw * left, ego_y + sin_yaw * forward + cos_yaw * left};
  }
  Eigen::Vector2d camera_xy() const {
    return {ego_x + cos_yaw * mount_forward, ego_y + sin_yaw * mount_forward};
  }
};

// The view of a camera config from an ego pose.
View make_view(const CameraConfig& config, double focal, const Pose2& ego) {
  const double pitch = config.pitch_deg * kPi / 180.0;
  const double cx = 0.5 * config.width, cy = 0.5 * config.height;
  return View{.ego_x = ego.x_m,
              .ego_y = ego.y_m,
              .cos_yaw = std::cos(ego.yaw_rad),
              .sin_yaw = std::sin(ego.yaw_rad),
              .mount_forward = config.forward_m,
              .mount_height = config.height_m,
              .cos_pitch = std::cos(pitch),
              .sin_pitch = std::sin(pitch),
              .focal = focal,
              .cx = cx,
              .cy = cy,
              .tan_x = cx / focal,
              .tan_y = cy / focal,
              .near = config.near_m,
              .far = config.far_m,
              .width = config.width,
              .height = config.height};
}

// A clipped, projected convex polygon: at most the 4 corners of a face plus one per clip.
struct ScreenPolygon {
  std::array<double, 8> u, v;
  int size = 0;
};

// Sutherland-Hodgman clip of a convex 3D polygon against the plane z = near, keeping z >= near,
// then perspective projection. Clipping before projecting is what keeps faces that cross the
// camera plane correct: their parts behind the camera would otherwise project mirrored.
ScreenPolygon clip_and_project(const View& view, const Eigen::Vector3d* in, int count) {
  std::array<Eigen::Vector3d, 8> kept;
  int n = 0;
  for (int k = 0; k < count; ++k) {
    const Eigen::Vector3d& a = in[k];
    const Eigen::Vector3d& b = in[(k + 1) % count];
    const bool a_in = a.z() >= view.near;
    const bool b_in = b.z() >= view.near;
    if (a_in) kept[n++] = a;
    if (a_in != b_in) {
      const double t = (view.near - a.z()) / (b.z() - a.z());
      kept[n++] = a + t * (b - a);
    }
  }
  ScreenPolygon out;
  out.size = n;
  for (int k = 0; k < n; ++k) {
    out.u[k] = view.focal * kept[k].x() / kept[k].z() + view.cx;
    out.v[k] = view.focal * kept[k].y() / kept[k].z() + view.cy;
  }
  return out;
}

// Fills the pixels whose centres lie inside one planar convex face, where the face is nearer
// than what the 1/z buffer holds. For a plane n . P = d seen along the ray
// r = ((u - cx) / f, (v - cy) / f, 1), 1/z = (n . r) / d is affine in (u, v), so depth is exact
// per pixel and boxes occlude each other correctly whatever their sizes.
void fill_face(const View& view, const Eigen::Vector3d* corners, std::uint8_t cls,
               cv::Mat& class_ids, std::vector<float>& inv_depth) {
  const Eigen::Vector3d normal = (corners[1] - corners[0]).cross(corners[3] - corners[0]);
  const double d = normal.dot(corners[0]);
  if (std::abs(d) < 1e-9 * normal.norm()) return;  // seen edge-on: covers no area
  const double a_u = normal.x() / (view.focal * d);
  const double a_v = normal.y() / (view.focal * d);
  const double a_0 =
      (normal.z() - normal.x() * view.cx / view.focal - normal.y() * view.cy / view.focal) / d;

  const ScreenPolygon poly = clip_and_project(view, corners, 4);
  if (poly.size < 3) return;
  double v_min = poly.v[0], v_max = poly.v[0];
  for (int k = 1; k < poly.size; ++k) {
    v_min = std::min(v_min, poly.v[k]);
    v_max = std::max(v_max, poly.v[k]);
  }
  const int row_begin = std::max(0, static_cast<int>(std::ceil(std::max(v_min, -1.0) - 0.5)));
  const int row_end =
      std::min(view.height - 1, static_cast<int>(std::floor(std::min(v_max, 1e6) - 0.5)));
  for (int row = row_begin; row <= row_end; ++row) {
    const double vc = row + 0.5;
    // Span of this row inside the polygon: crossings of the row's centre line with the edges.
    double x_left = std::numeric_limits<double>::infinity();
    double x_right = -std::numeric_limits<double>::infinity();
    for (int k = 0; k < poly.size; ++k) {
      const int k1 = (k + 1) % poly.size;
      const double va = poly.v[k], vb = poly.v[k1];
      if ((va <= vc && vc < vb) || (vb <= vc && vc < va)) {
        const double x = poly.u[k] + (vc - va) * (poly.u[k1] - poly.u[k]) / (vb - va);
        x_left = std::min(x_left, x);
        x_right = std::max(x_right, x);
      }
    }
    if (!(x_left <= x_right)) continue;
    const int col_begin = std::max(0, static_cast<int>(std::ceil(std::max(x_left, -1.0) - 0.5)));
    const int col_end = std::min(
        view.width, static_cast<int>(std::ceil(std::min(x_right, view.width + 1.0) - 0.5)));
    std::uint8_t* ids = class_ids.ptr<std::uint8_t>(row);
    float* depth = inv_depth.data() + static_cast<std::size_t>(row) * view.width;
    const double row_term = a_v * vc + a_0;
    for (int col = col_begin; col < col_end; ++col) {
      const float inv_z = static_cast<float>(a_u * (col + 0.5) + row_term);
      if (inv_z > depth[col]) {
        depth[col] = inv_z;
        ids[col] = cls;
      }
    }
  }
}

// Draws the faces of one box that face the camera; culls boxes outside the view frustum.
void draw_box(const View& view, const Box& box, cv::Mat& class_ids, std::vector<float>& inv_depth) {
  const std::array<Eigen::Vector2d, 4> foot = detail::footprint(box);
  // Corners in camera coordinates: [0, 4) on the ground, [4, 8) on top, same order.
  std::array<Eigen::Vector3d, 8> c;
  for (int k = 0; k < 4; ++k) {
    c[k] = view.to_camera(foot[k].x(), foot[k].y(), 0.0);
    c[k + 4] = view.to_camera(foot[k].x(), foot[k].y(), box.height_m);
  }
  // Frustum culling: drop the box if all corners are outside one of the six planes (each a
  // half-space test, valid for corners behind the camera too).
  auto all = [&](auto outside) {
    for (const Eigen::Vector3d& p : c)
      if (!outside(p)) return false;
    return true;
  };
  if (all([&](const Eigen::Vector3d& p) { return p.z() < view.near; }) ||
      all([&](const Eigen::Vector3d& p) { return p.z() > view.far; }) ||
      all([&](const Eigen::Vector3d& p) { return p.x() > view.tan_x * p.z(); }) ||
      all([&](const Eigen::Vector3d& p) { return p.x() < -view.tan_x * p.z(); }) ||
      all([&](const Eigen::Vector3d& p) { return p.y() > view.tan_y * p.z(); }) ||
      all([&](const Eigen::Vector3d& p) { return p.y() < -view.tan_y * p.z(); }))
    return;

  // Back-face culling: a side is visible when the camera is on its outer side (footprint is
  // counter-clockwise, so the outward normal is the edge direction turned clockwise).
  const std::uint8_t cls = static_cast<std::uint8_t>(box.cls);
  const Eigen::Vector2d camera = view.camera_xy();
  for (int k = 0; k < 4; ++k) {
    const int k1 = (k + 1) % 4;
    const Eigen::Vector2d edge = foot[k1] - foot[k];
    const Eigen::Vector2d outward(edge.y(), -edge.x());
    if ((camera - foot[k]).dot(outward) <= 0.0) continue;
    const Eigen::Vector3d face[4] = {c[k], c[k1], c[k1 + 4], c[k + 4]};
    fill_face(view, face, cls, class_ids, inv_depth);
  }
  if (view.mount_height > box.height_m) {
    const Eigen::Vector3d top[4] = {c[4], c[5], c[6], c[7]};
    fill_face(view, top, cls, class_ids, inv_depth);
  }
}

}  // namespace

SemanticCamera::SemanticCamera(const CameraConfig& config, const StaticScene& scene)
    : SemanticCamera(config, std::make_shared<const SceneCache>(scene)) {}

SemanticCamera::SemanticCamera(const CameraConfig& config, std::shared_ptr<const SceneCache> scene)
    : config_(config), scene_(std::move(scene)) {
  validate(config_);
  INDRIVE_CHECK(scene_ != nullptr) << "SemanticCamera needs a scene cache";
  focal_px_ = 0.5 * config_.width / std::tan(0.5 * config_.hfov_deg * kPi / 180.0);
  const double pitch = config_.pitch_deg * kPi / 180.0;
  const double cos_pitch = std::cos(pitch), sin_pitch = std::sin(pitch);
  const double cx = 0.5 * config_.width, cy = 0.5 * config_.height;

  // Per row: where the rays of pixel centres meet the ground. A ray (a, b, 1) in the camera
  // frame points (cos p - b sin p, -a, -(b cos p + sin p)) in the ego frame; its downward part
  // does not depend on the column a, so the whole row meets the ground at one depth t.
  rows_.resize(config_.height);
  for (int row = 0; row < config_.height; ++row) {
    RowGround& g = rows_[row];
    const double b = (row + 0.5 - cy) / focal_px_;
    const double down = b * cos_pitch + sin_pitch;
    if (down <= 1e-12) {
      g.kind = RowGround::Kind::kSky;
      continue;
    }
    const double depth = config_.height_m / down;  // camera depth of this row's ground points
    if (depth > config_.far_m) {
      g.kind = RowGround::Kind::kBeyondFar;
      continue;
    }
    g.kind = RowGround::Kind::kGround;
    g.forward_m = config_.forward_m + depth * (cos_pitch - b * sin_pitch);
    g.left0_m = -depth * (0.5 - cx) / focal_px_;
    g.step_forward_m = 0.0;
    g.step_left_m = -depth / focal_px_;
    g.line_level = scene_->line_level_for(depth / focal_px_);
  }
  inv_depth_.assign(static_cast<std::size_t>(config_.width) * config_.height, 0.0f);
}

void SemanticCamera::render(const Pose2& ego, std::span<const Box> vehicles,
                            cv::Mat& class_ids) const {
  const int width = config_.width, height = config_.height;
  class_ids.create(height, width, CV_8UC1);
  const double cos_yaw = std::cos(ego.yaw_rad), sin_yaw = std::sin(ego.yaw_rad);

  // Ground and sky, row by row. Map coordinates of a row's pixels are affine in the column.
  const SceneCache& scene = *scene_;
  const cv::Mat& base = scene.ground_map();
  const double res = scene.resolution_m();
  const Eigen::Vector2d origin = scene.origin();
  const std::uint8_t sky = static_cast<std::uint8_t>(SemanticClass::kSky);
  const std::uint8_t fallback = static_cast<std::uint8_t>(scene.ground_class());
  const std::uint8_t road_line = static_cast<std::uint8_t>(SemanticClass::kRoadLine);
  const double map_cols = base.cols, map_rows = base.rows;
  for (int row = 0; row < height; ++row) {
    const RowGround& g = rows_[row];
    std::uint8_t* out = class_ids.ptr<std::uint8_t>(row);
    if (g.kind != RowGround::Kind::kGround) {
      std::memset(out, g.kind == RowGround::Kind::kSky ? sky : fallback, width);
      continue;
    }
    const double x0 = ego.x_m + cos_yaw * g.forward_m - sin_yaw * g.left0_m;
    const double y0 = ego.y_m + sin_yaw * g.forward_m + cos_yaw * g.left0_m;
    const double dx = cos_yaw * g.step_forward_m - sin_yaw * g.step_left_m;
    const double dy = sin_yaw * g.step_forward_m + cos_yaw * g.step_left_m;
    const double col0 = (x0 - origin.x()) / res, col_step = dx / res;
    const double row0 = (origin.y() - y0) / res, row_step = -dy / res;
    const int level = g.line_level;
    const cv::Mat& lines = scene.line_level(level);
    for (int col = 0; col < width; ++col) {
      const double mc = col0 + col * col_step;
      const double mr = row0 + col * row_step;
      if (!(mc >= 0.0 && mr >= 0.0 && mc < map_cols && mr < map_rows)) {
        out[col] = fallback;
        continue;
      }
      const int ci = static_cast<int>(mc), ri = static_cast<int>(mr);
      out[col] = level > 0 && lines.ptr<std::uint8_t>(ri >> level)[ci >> level] != 0
                     ? road_line
                     : base.ptr<std::uint8_t>(ri)[ci];
    }
  }

  // Boxes over the ground: static ones inside the frustum's bounding rectangle, then vehicles.
  const View view = make_view(config_, focal_px_, ego);
  std::fill(inv_depth_.begin(), inv_depth_.end(), 0.0f);
  Eigen::Vector2d lo = view.camera_xy(), hi = lo;
  for (const double sx : {-1.0, 1.0})
    for (const double sy : {-1.0, 1.0}) {
      const Eigen::Vector2d p = view.to_world_xy(
          Eigen::Vector3d(sx * view.tan_x * view.far, sy * view.tan_y * view.far, view.far));
      lo = lo.cwiseMin(p);
      hi = hi.cwiseMax(p);
    }
  candidates_.clear();
  scene.boxes_in(lo, hi, candidates_);
  for (const int index : candidates_) draw_box(view, scene.boxes()[index], class_ids, inv_depth_);
  for (const Box& vehicle : vehicles) draw_box(view, vehicle, class_ids, inv_depth_);
}

cv::Mat SemanticCamera::render(const Pose2& ego, std::span<const Box> vehicles) const {
  cv::Mat class_ids;
  render(ego, vehicles, class_ids);
  return class_ids;
}

std::optional<Eigen::Vector2d> SemanticCamera::project(const Pose2& ego,
                                                       const Eigen::Vector3d& world) const {
  const View view = make_view(config_, focal_px_, ego);
  const Eigen::Vector3d c = view.to_camera(world.x(), world.y(), world.z());
  if (c.z() < view.near) return std::nullopt;
  return Eigen::Vector2d(view.focal * c.x() / c.z() + view.cx,
                         view.focal * c.y() / c.z() + view.cy);
}

}  // namespace indrive::env
