#include <crumple/render/colouring.hpp>

#include <crumple/core/error.hpp>
#include <crumple/render/rasteriser.hpp>

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
