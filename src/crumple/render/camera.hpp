#pragma once
/// \file
/// An orbit camera shared by `crumple render` (software rasteriser) and `crumple-view`
/// (OpenGL), so both frame a scene the same way. y is up; yaw 0 looks from +z towards −z.
///
/// The eye sits at `target + distance · (cos p sin y, sin p, cos p cos y)` for yaw y and
/// pitch p; the projection is perspective with vertical field of view `fov_deg`.

#include <crumple/core/types.hpp>
#include <crumple/mesh/mesh.hpp>

#include <optional>

namespace crumple::render {

/// A point projected to the screen: pixel coordinates (x right, y down, pixel centres at
/// half-integers) and the view-space depth along the viewing direction (scene units, > 0 in
/// front of the eye).
struct ScreenPoint {
  double x = 0;
  double y = 0;
  double depth = 0;
};

struct Camera {
  Vec3 target = Vec3::Zero();
  double yaw_deg = 30;    ///< rotation about the y axis, degrees
  double pitch_deg = 20;  ///< elevation above the xz plane, degrees, clamped to ±89
  double distance = 3;    ///< eye–target distance, scene units (> 0)
  double fov_deg = 40;    ///< vertical field of view, degrees

  /// Points at the centre of `bounds` and sets the smallest distance at which the whole box
  /// projects inside a view of width/height ratio `aspect`, plus an 8% margin. Keeps yaw,
  /// pitch and the field of view.
  void fit(const Bounds& bounds, double aspect = 4.0 / 3.0);
  /// Adds to yaw and pitch (degrees); pitch stays in [−89, 89].
  void orbit(double dyaw_deg, double dpitch_deg);
  /// Moves the target in the view plane by fractions of the view height at the target.
  void pan(double dx, double dy);
  /// Multiplies the distance by `factor` (> 0).
  void zoom(double factor);

  Vec3 eye() const;
  /// Unit vectors of the view frame: right, up, and forward (from the eye to the target).
  Vec3 right() const;
  Vec3 up() const;
  Vec3 forward() const;

  /// World → view transform (OpenGL convention: the eye looks along −z).
  Eigen::Matrix4d view_matrix() const;
  /// Perspective projection (OpenGL clip space) with near = distance/100, far = 100·distance.
  Eigen::Matrix4d projection_matrix(double aspect) const;

  /// Projects a point for a `width` × `height` image; empty when it is behind the eye.
  std::optional<ScreenPoint> project(const Vec3& p, int width, int height) const;
  /// The world point on the ray through pixel (x, y) at view-space depth `depth` (inverse of
  /// `project`).
  Vec3 unproject(double x, double y, double depth, int width, int height) const;
};

/// The vertex whose projection is closest to pixel (x, y), within `radius` pixels, the nearest
/// to the eye among ties within 1 pixel; -1 when none.
Index pick_vertex(const Camera& camera, PositionsView positions, double x, double y, int width,
                  int height, double radius = 12);

}  // namespace crumple::render
