#pragma once
// OpenGL 3.3 core drawing of a cloth frame for crumple-view: a shaded surface (flat, two-sided
// headlight lighting as in crumple::render's rasteriser), lines (wireframe, springs, colliding
// edges, contact segments, overlays) and points (masses). Only drawing: the geometry and the
// colouring come from the library (crumple::render::colouring).

#include <crumple/render/camera.hpp>
#include <crumple/render/colouring.hpp>
#include <crumple/render/rasteriser.hpp>

#include <span>
#include <vector>

namespace crumple::viewer {

/// A coloured vertex of a line or point batch.
struct ColouredVertex {
  float x, y, z;
  float r, g, b;
};

/// Collects lines and points, then draws them in one call each.
struct Batch {
  std::vector<ColouredVertex> lines;  ///< two vertices a segment
  std::vector<ColouredVertex> points;
  void line(const Vec3& a, const Vec3& b, render::Rgb c);
  void point(const Vec3& p, render::Rgb c);
  void clear() {
    lines.clear();
    points.clear();
  }
};

class GlDraw {
 public:
  /// Compiles the shaders; needs a current OpenGL 3.3 core context. Throws on failure.
  GlDraw();
  ~GlDraw();
  GlDraw(const GlDraw&) = delete;
  GlDraw& operator=(const GlDraw&) = delete;

  /// Clears the `width` × `height` framebuffer to the palette background and sets the camera.
  void begin(const render::Camera& camera, int width, int height, const render::Palette& palette);
  /// The surface of a mesh, front / back colours, lit like the software rasteriser.
  void surface(std::span<const Face> faces, PositionsView positions, const render::Palette& palette,
               const render::Lighting& lighting);
  /// Lines `width` pixels wide, then points `size` pixels across, depth-tested.
  void batch(const Batch& batch, float line_width, float point_size);

 private:
  unsigned mesh_program_ = 0, line_program_ = 0;
  unsigned vao_ = 0, mesh_vbo_ = 0, mesh_ebo_ = 0, line_vbo_ = 0;
  float mvp_[16] = {}, mv_[16] = {};
};

}  // namespace crumple::viewer
