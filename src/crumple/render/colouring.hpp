#pragma once
/// \file
/// What a picture of a cloth shows, shared by `crumple render` and `crumple-view` so both
/// colour a frame the same way:
///  - the surface, shaded with two-sided lighting (`front` / `back` colours);
///  - optionally its edges (wireframe), or only the masses and springs (as in the thesis);
///  - edges in collision in red: both edges of every EE contact and the three sides of the face
///    of every VF contact (the rule of `sim::collision_share`);
///  - every VF contact as a short segment from the vertex to its closest point on the face;
///  - the rigid obstacles (sphere, box, floor) in grey.

#include <crumple/detect/contact.hpp>
#include <crumple/mesh/mesh.hpp>
#include <crumple/render/camera.hpp>
#include <crumple/render/picture.hpp>
#include <crumple/response/obstacle.hpp>

#include <span>
#include <vector>

namespace crumple::render {

/// Colours of a picture.
struct Palette {
  Rgb background{255, 255, 255};
  Rgb front{120, 160, 215};    ///< surface, side where the faces turn counter-clockwise
  Rgb back{225, 200, 120};     ///< surface, other side
  Rgb edge{40, 50, 70};        ///< wireframe edges
  Rgb colliding{230, 20, 20};  ///< edges in collision
  Rgb contact{20, 150, 40};    ///< VF contact segments
  Rgb mass{30, 30, 30};        ///< particles (masses-and-springs mode)
  Rgb pinned{200, 30, 200};    ///< pinned particles
  Rgb spring{90, 110, 140};    ///< springs (masses-and-springs mode)
  Rgb obstacle{185, 185, 180};  ///< rigid obstacles
};

/// What to draw.
struct DrawOptions {
  bool surface = true;           ///< shaded triangles
  bool wireframe = false;        ///< every mesh edge
  bool masses_springs = false;   ///< particles and springs instead of the surface
  bool colliding_edges = true;   ///< red edges in collision
  bool contact_segments = true;  ///< VF contacts as segments
  double edge_width = 1;         ///< output pixels
  double colliding_width = 2;    ///< output pixels
  double mass_radius = 2;        ///< output pixels
  Palette palette;
};

/// A triangle mesh of an obstacle's surface, for drawing: a sphere as a 32 × 16 UV sphere, a
/// box as 12 triangles, a plane as a 16 × 16 grid `extent` wide around the point of the plane
/// nearest `centre` (a floor under the cloth).
struct ShapeMesh {
  std::vector<Vec3> positions;
  std::vector<Face> faces;
};

/// A frame to draw: connectivity, positions (#V), its contacts, and optionally springs and
/// pinned flags (masses-and-springs mode; springs default to the mesh edges).
struct Frame {
  const Topology* topology = nullptr;
  PositionsView positions;
  const ContactSet* contacts = nullptr;  ///< may be null: nothing in collision
  std::span<const Edge> springs;         ///< particle pairs; empty = the mesh edges
  std::span<const bool> pinned;          ///< #V flags or empty
  std::span<const ShapeMesh> obstacles;  ///< rigid obstacles (`obstacle_meshes`)
};

ShapeMesh shape_mesh(const response::Shape& shape, const Vec3& centre, Scalar extent);
/// The meshes of `obstacles` at time `t`, drawn around a cloth at `cloth` (a floor spans three
/// times the cloth's bounding-box diagonal around its centre): what both front ends draw.
std::vector<ShapeMesh> obstacle_meshes(std::span<const response::Obstacle> obstacles, Scalar t,
                                       PositionsView cloth);

/// Per mesh edge: true when the edge is in collision (see the file comment).
std::vector<bool> colliding_edges(const Topology& topology, const ContactSet& contacts);

/// A segment between two points.
struct Segment {
  Vec3 a, b;
};
/// One segment per VF contact, from the vertex to its closest point on the face.
std::vector<Segment> contact_segments(const Topology& topology, PositionsView positions,
                                      const ContactSet& contacts);

/// Renders a frame with the software rasteriser at `width` × `height`; `supersample` 1..4.
Picture render_frame(const Frame& frame, const Camera& camera, int width, int height,
                     const DrawOptions& options = {}, int supersample = 2);

}  // namespace crumple::render
