#pragma once
/// \file
/// A small software rasteriser for pictures without a display (`crumple render`, tests):
/// z-buffered triangles with two-sided Lambert + ambient lighting, depth-tested thick lines
/// and round points, optional supersampling (box-filtered on `picture()`).
///
/// Depth is the view-space distance along the viewing direction; 1/depth is interpolated
/// linearly in screen space (exact for planar primitives under perspective). Primitives with a
/// corner closer to the eye than `camera.distance / 1000` are skipped (triangles) or clipped
/// (lines). Lines and points are drawn slightly in front of the surface (`line_depth_bias`,
/// relative to the depth) so edges lying on it stay visible.

#include <crumple/render/camera.hpp>
#include <crumple/render/picture.hpp>

#include <vector>

namespace crumple::render {

/// Light of the shaded surface: a headlight, so the side of the surface facing the viewer is
/// lit whichever side it is (two-sided lighting): colour × (ambient + diffuse · max(0, n·l)),
/// n the face normal turned towards the eye, l the unit direction towards the light.
struct Lighting {
  double ambient = 0.35;
  double diffuse = 0.65;
  /// Direction towards the light in view coordinates (x right, y up, z towards the viewer).
  Vec3 direction = Vec3(-0.3, 0.5, 1.0).normalized();
};

class Rasteriser {
 public:
  /// An image of `width` × `height` pixels seen through `camera`, cleared to `background`;
  /// `supersample` (1..4) samples per pixel along each axis.
  Rasteriser(int width, int height, const Camera& camera, Rgb background, int supersample = 1);

  /// A lit triangle: `front` where the corners (a, b, c) turn counter-clockwise as seen from
  /// the eye, `back` otherwise.
  void triangle(const Vec3& a, const Vec3& b, const Vec3& c, Rgb front, Rgb back);
  /// A segment `width_px` output pixels wide, unlit, depth-tested.
  void line(const Vec3& a, const Vec3& b, Rgb colour, double width_px = 1);
  /// A disc of radius `radius_px` output pixels, unlit, depth-tested.
  void point(const Vec3& p, Rgb colour, double radius_px = 2);

  /// The image at the output size (supersamples averaged).
  Picture picture() const;

  Lighting lighting;
  double line_depth_bias = 2e-3;  ///< lines and points are drawn this fraction nearer

 private:
  struct Projected {
    double x, y, inv_depth;
  };
  bool project(const Vec3& p, Projected& out) const;
  void stamp(double cx, double cy, double inv_depth, double half, bool round, Rgb colour);

  int width_, height_, ss_;
  int w_, h_;  // supersampled size
  Camera camera_;
  double near_;
  std::vector<Rgb> colour_;
  std::vector<double> inv_depth_;  // 0 = empty (infinitely far)
};

}  // namespace crumple::render
