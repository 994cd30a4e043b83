#include <crumple/render/colouring.hpp>

#include <crumple/core/error.hpp>
#include <crumple/render/rasteriser.hpp>

#include <cmath>
#include <numbers>
#include <type_traits>

namespace crumple::render {

std::vector<bool> colliding_edges(const Topology& topology, const ContactSet& contacts) {
  std::vector<bool> out(static_cast<std::size_t>(topology.num_edges()), false);
  for (const EdgeEdgeContact& c : contacts.ee) {
    out.at(static_cast<std::size_t>(c.edge0)) = true;
    out.at(static_cast<std::size_t>(c.edge1)) = true;
  }
  for (const VertexFaceContact& c : contacts.vf) {
    for (const Index e : topology.face_edges(c.face)) out.at(static_cast<std::size_t>(e)) = true;
  }
  return out;
}

std::vector<Segment> contact_segments(const Topology& topology, PositionsView positions,
                                      const ContactSet& contacts) {
  std::vector<Segment> out;
  out.reserve(contacts.vf.size());
  for (const VertexFaceContact& c : contacts.vf) {
    const Face& f = topology.face(c.face);
    const Vec3 closest = c.barycentric[0] * positions[static_cast<std::size_t>(f[0])] +
                         c.barycentric[1] * positions[static_cast<std::size_t>(f[1])] +
                         c.barycentric[2] * positions[static_cast<std::size_t>(f[2])];
    out.push_back({positions[static_cast<std::size_t>(c.vertex)], closest});
  }
  return out;
}

namespace {

/// Quads of an (nu + 1) × (nv + 1) grid of points `at(i, j)`, as two triangles each.
template <class At>
void grid(ShapeMesh& m, int nu, int nv, At at) {
  const auto base = static_cast<Index>(m.positions.size());
  for (int j = 0; j <= nv; ++j) {
    for (int i = 0; i <= nu; ++i) m.positions.push_back(at(i, j));
  }
  const auto id = [&](int i, int j) { return base + static_cast<Index>(j * (nu + 1) + i); };
  for (int j = 0; j < nv; ++j) {
    for (int i = 0; i < nu; ++i) {
      m.faces.push_back({id(i, j), id(i + 1, j), id(i + 1, j + 1)});
      m.faces.push_back({id(i, j), id(i + 1, j + 1), id(i, j + 1)});
    }
  }
}

}  // namespace

ShapeMesh shape_mesh(const response::Shape& shape, const Vec3& centre, Scalar extent) {
  ShapeMesh m;
  std::visit(
      [&](const auto& s) {
        using T = std::decay_t<decltype(s)>;
        if constexpr (std::is_same_v<T, response::Sphere>) {
          grid(m, 32, 16, [&](int i, int j) {
            const double phi = 2 * std::numbers::pi * i / 32, theta = std::numbers::pi * j / 16;
            return Vec3(s.center + s.radius * Vec3(std::sin(theta) * std::cos(phi), std::cos(theta),
                                                   std::sin(theta) * std::sin(phi)));
          });
        } else if constexpr (std::is_same_v<T, response::Box>) {
          // Each face: a 1 × 1 grid on the side at ±1 along axis a, spanned by the two others.
          for (int a = 0; a < 3; ++a) {
            for (const double side : {-1.0, 1.0}) {
              const int b = (a + 1) % 3, c = (a + 2) % 3;
              grid(m, 1, 1, [&](int i, int j) {
                Vec3 local = Vec3::Zero();
                local[a] = side;
                local[b] = 2.0 * i - 1;
                local[c] = 2.0 * j - 1;
                return Vec3(s.center + s.rotation * local.cwiseProduct(s.half_extents));
              });
            }
          }
        } else {
          const Vec3 n = s.normal.normalized();
          const Vec3 u = (std::abs(n.x()) < 0.9 ? Vec3::UnitX() : Vec3::UnitY()).cross(n).normalized();
          const Vec3 v = n.cross(u);
          const Vec3 o = centre - (centre - s.point).dot(n) * n;
          grid(m, 16, 16, [&](int i, int j) { return Vec3(o + extent * ((i / 16.0 - 0.5) * u + (j / 16.0 - 0.5) * v)); });
        }
      },
      shape);
  return m;
}

std::vector<ShapeMesh> obstacle_meshes(std::span<const response::Obstacle> obstacles, Scalar t,
                                       PositionsView cloth) {
  std::vector<ShapeMesh> out;
  if (obstacles.empty()) return out;
  const Bounds box = compute_bounds(cloth);
  for (const response::Obstacle& o : obstacles) {
    out.push_back(shape_mesh(o.at_time(t), (box.min + box.max) / 2, 3 * box.diagonal()));
  }
  return out;
}

Picture render_frame(const Frame& frame, const Camera& camera, int width, int height,
                     const DrawOptions& options, int supersample) {
  CRUMPLE_CHECK(frame.topology != nullptr, "a frame needs its topology");
  CRUMPLE_CHECK(frame.positions.size() == static_cast<std::size_t>(frame.topology->num_vertices()),
                "one position per vertex");
  const Palette& pal = options.palette;
  Rasteriser r(width, height, camera, pal.background, supersample);
  const Topology& topo = *frame.topology;
  const auto x = [&](Index i) -> const Vec3& {
    return frame.positions[static_cast<std::size_t>(i)];
  };

  for (const ShapeMesh& m : frame.obstacles) {
    for (const Face& f : m.faces) {
      r.triangle(m.positions[static_cast<std::size_t>(f[0])], m.positions[static_cast<std::size_t>(f[1])],
                 m.positions[static_cast<std::size_t>(f[2])], pal.obstacle, pal.obstacle);
    }
  }
  if (options.masses_springs) {
    if (frame.springs.empty()) {
      for (const Edge& e : topo.edges()) r.line(x(e[0]), x(e[1]), pal.spring, options.edge_width);
    } else {
      for (const Edge& e : frame.springs) r.line(x(e[0]), x(e[1]), pal.spring, options.edge_width);
    }
    for (std::size_t i = 0; i < frame.positions.size(); ++i) {
      const bool pinned = i < frame.pinned.size() && frame.pinned[i];
      r.point(frame.positions[i], pinned ? pal.pinned : pal.mass,
              pinned ? 1.5 * options.mass_radius : options.mass_radius);
    }
  } else {
    if (options.surface) {
      for (const Face& f : topo.faces()) r.triangle(x(f[0]), x(f[1]), x(f[2]), pal.front, pal.back);
    }
    if (options.wireframe || !options.surface) {
      for (const Edge& e : topo.edges()) r.line(x(e[0]), x(e[1]), pal.edge, options.edge_width);
    }
  }
  if (frame.contacts != nullptr) {
    if (options.colliding_edges) {
      const std::vector<bool> hit = colliding_edges(topo, *frame.contacts);
      for (Index e = 0; e < topo.num_edges(); ++e) {
        if (!hit[static_cast<std::size_t>(e)]) continue;
        r.line(x(topo.edge(e)[0]), x(topo.edge(e)[1]), pal.colliding, options.colliding_width);
      }
    }
    if (options.contact_segments) {
      for (const Segment& s : contact_segments(topo, frame.positions, *frame.contacts)) {
        r.line(s.a, s.b, pal.contact, options.edge_width);
      }
    }
  }
  return r.picture();
}

}  // namespace crumple::render
