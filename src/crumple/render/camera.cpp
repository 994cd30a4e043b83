#include <crumple/render/camera.hpp>

#include <algorithm>
#include <cmath>
#include <numbers>

namespace crumple::render {

namespace {

double radians(double degrees) { return degrees * std::numbers::pi / 180.0; }

}  // namespace

void Camera::fit(const Bounds& bounds, double aspect) {
  if (!bounds.min.allFinite() || !bounds.max.allFinite()) return;
  target = 0.5 * (bounds.min + bounds.max);
  const double tan_v = std::tan(0.5 * radians(fov_deg));
  const double tan_h = tan_v * std::max(aspect, 1e-3);
  // Smallest distance at which every corner of the box projects inside the view:
  // depth = d + (p − target)·forward must be >= |(p − target)·right| / tan_h and
  // >= |(p − target)·up| / tan_v.
  const Vec3 r = right(), u = up(), f = forward();
  double needed = 1e-9;
  for (int i = 0; i < 8; ++i) {
    const Vec3 p((i & 1) ? bounds.max.x() : bounds.min.x(),
                 (i & 2) ? bounds.max.y() : bounds.min.y(),
                 (i & 4) ? bounds.max.z() : bounds.min.z());
    const Vec3 q = p - target;
    needed = std::max(
        {needed, std::abs(q.dot(r)) / tan_h - q.dot(f), std::abs(q.dot(u)) / tan_v - q.dot(f)});
  }
  distance = 1.08 * needed + 1e-3 * bounds.diagonal();
}

void Camera::orbit(double dyaw_deg, double dpitch_deg) {
  yaw_deg = std::fmod(yaw_deg + dyaw_deg, 360.0);
  pitch_deg = std::clamp(pitch_deg + dpitch_deg, -89.0, 89.0);
}

void Camera::pan(double dx, double dy) {
  const double height = 2 * distance * std::tan(0.5 * radians(fov_deg));
  target += (dx * height) * right() + (dy * height) * up();
}

void Camera::zoom(double factor) {
  if (factor > 0 && std::isfinite(factor)) distance = std::max(distance * factor, 1e-9);
}

Vec3 Camera::eye() const {
  const double y = radians(yaw_deg), p = radians(pitch_deg);
  return target +
         distance * Vec3(std::cos(p) * std::sin(y), std::sin(p), std::cos(p) * std::cos(y));
}

Vec3 Camera::forward() const { return (target - eye()).normalized(); }

Vec3 Camera::right() const {
  const double y = radians(yaw_deg);
  return Vec3(std::cos(y), 0, -std::sin(y));
}

Vec3 Camera::up() const { return right().cross(forward()).normalized(); }

Eigen::Matrix4d Camera::view_matrix() const {
  const Vec3 r = right(), u = up(), f = forward(), e = eye();
  Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
  m.block<1, 3>(0, 0) = r.transpose();
  m.block<1, 3>(1, 0) = u.transpose();
  m.block<1, 3>(2, 0) = -f.transpose();
  m(0, 3) = -r.dot(e);
  m(1, 3) = -u.dot(e);
  m(2, 3) = f.dot(e);
  return m;
}

Eigen::Matrix4d Camera::projection_matrix(double aspect) const {
  const double n = distance / 100, far = distance * 100;
  const double f = 1 / std::tan(0.5 * radians(fov_deg));
  Eigen::Matrix4d m = Eigen::Matrix4d::Zero();
  m(0, 0) = f / aspect;
  m(1, 1) = f;
  m(2, 2) = (far + n) / (n - far);
  m(2, 3) = 2 * far * n / (n - far);
  m(3, 2) = -1;
  return m;
}

std::optional<ScreenPoint> Camera::project(const Vec3& p, int width, int height) const {
  const Vec3 d = p - eye();
  const double depth = d.dot(forward());
  if (!(depth > 1e-12)) return std::nullopt;
  const double f = 1 / std::tan(0.5 * radians(fov_deg));
  const double aspect = static_cast<double>(width) / height;
  const double nx = f / aspect * d.dot(right()) / depth;
  const double ny = f * d.dot(up()) / depth;
  return ScreenPoint{(0.5 + 0.5 * nx) * width, (0.5 - 0.5 * ny) * height, depth};
}

Vec3 Camera::unproject(double x, double y, double depth, int width, int height) const {
  const double f = 1 / std::tan(0.5 * radians(fov_deg));
  const double aspect = static_cast<double>(width) / height;
  const double nx = 2 * x / width - 1, ny = 1 - 2 * y / height;
  return eye() + depth * (forward() + (nx * aspect / f) * right() + (ny / f) * up());
}

Index pick_vertex(const Camera& camera, PositionsView positions, double x, double y, int width,
                  int height, double radius) {
  Index best = -1;
  double best_d2 = radius * radius, best_depth = 0;
  for (std::size_t i = 0; i < positions.size(); ++i) {
    const auto s = camera.project(positions[i], width, height);
    if (!s) continue;
    const double d2 = (s->x - x) * (s->x - x) + (s->y - y) * (s->y - y);
    if (d2 > radius * radius) continue;
    const bool closer =
        d2 + 1 < best_d2 || (best >= 0 && d2 <= best_d2 + 1 && s->depth < best_depth);
    if (best < 0 || closer) {
      best = static_cast<Index>(i);
      best_d2 = d2;
      best_depth = s->depth;
    }
  }
  return best;
}

}  // namespace crumple::render
