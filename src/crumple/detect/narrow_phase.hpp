#pragma once
/// \file
/// The narrow phase shared by every detector: one function per primitive pair that applies the
/// contact definition (detector.hpp) with the geometry kernels and fills a typed contact. Every
/// detector calls these, so distances are bit-identical across methods. Topological exclusion
/// (adjacent pairs) is the caller's job: these functions assume a non-adjacent pair.

#include <crumple/core/types.hpp>
#include <crumple/detect/contact.hpp>
#include <crumple/geometry/distance.hpp>
#include <crumple/mesh/mesh.hpp>

#include <cmath>
#include <optional>

namespace crumple::narrow {

inline const Vec3& at(PositionsView x, Index i) { return x[static_cast<std::size_t>(i)]; }

/// Vertex v at p against face f with corners a, b, c in face order (v not a corner of f); a
/// contact when the distance is < h (`sqr_thickness` = h^2). The normal points from the face to
/// the vertex. The squared distance, contact or not, goes to `*sqr_distance` when given.
inline std::optional<VertexFaceContact> vertex_face(Index v, const Vec3& p, Index f, const Vec3& a,
                                                    const Vec3& b, const Vec3& c, Scalar sqr_thickness,
                                                    Scalar* sqr_distance = nullptr) {
  const geometry::PointTriangleResult r = geometry::point_triangle(p, a, b, c);
  if (sqr_distance != nullptr) *sqr_distance = r.sqr_distance;
  if (!(r.sqr_distance < sqr_thickness)) return std::nullopt;
  VertexFaceContact contact;
  contact.vertex = v;
  contact.face = f;
  contact.distance = std::sqrt(r.sqr_distance);
  contact.barycentric = r.barycentric;
  const Vec3 away = p - r.closest;
  const Scalar away_norm = away.norm();
  if (away_norm > 0) {
    contact.normal = away / away_norm;
  } else {
    const Vec3 n = (b - a).cross(c - a);
    const Scalar len = n.norm();
    contact.normal = len > 0 ? Vec3(n / len) : Vec3::Zero();
  }
  return contact;
}

/// Same, with the positions read from x.
inline std::optional<VertexFaceContact> vertex_face(PositionsView x, const Topology& topo, Index v,
                                                    Index f, Scalar sqr_thickness) {
  const Face& t = topo.face(f);
  return vertex_face(v, at(x, v), f, at(x, t[0]), at(x, t[1]), at(x, t[2]), sqr_thickness);
}

/// Edges e0 = ea and e1 = eb (sharing no vertex) at positions p0, p1 (of ea[0], ea[1]) and q0,
/// q1 (of eb[0], eb[1]); a contact when the distance is < h. The contact is order-normalised (see
/// `EdgeEdgeContact`). Callers pass e0 < e1, each edge as the mesh stores it, so that every
/// detector evaluates a pair in the same order and gets the same bits. The squared distance,
/// contact or not, goes to `*sqr_distance` when given.
inline std::optional<EdgeEdgeContact> edge_edge(Index e0, const Edge& ea, const Vec3& p0, const Vec3& p1,
                                                Index e1, const Edge& eb, const Vec3& q0, const Vec3& q1,
                                                Scalar sqr_thickness, Scalar* sqr_distance = nullptr) {
  const geometry::SegmentSegmentResult r = geometry::segment_segment(p0, p1, q0, q1);
  if (sqr_distance != nullptr) *sqr_distance = r.sqr_distance;
  if (!(r.sqr_distance < sqr_thickness)) return std::nullopt;
  const Scalar distance = std::sqrt(r.sqr_distance);
  Vec3 normal;
  const Vec3 gap = r.closest1 - r.closest0;
  const Scalar gap_norm = gap.norm();
  if (gap_norm > 0) {
    normal = gap / gap_norm;
  } else {
    const Vec3 n = (p1 - p0).cross(q1 - q0);
    const Scalar len = n.norm();
    normal = len > 0 ? Vec3(n / len) : Vec3::Zero();
  }
  return make_edge_edge_contact(e0, ea, e1, eb, distance, r.s, r.t, normal);
}

/// Edges e0 < e1 (sharing no vertex), with the positions read from x.
inline std::optional<EdgeEdgeContact> edge_edge(PositionsView x, const Topology& topo, Index e0,
                                                Index e1, Scalar sqr_thickness) {
  const Edge& ea = topo.edge(e0);
  const Edge& eb = topo.edge(e1);
  return edge_edge(e0, ea, at(x, ea[0]), at(x, ea[1]), e1, eb, at(x, eb[0]), at(x, eb[1]), sqr_thickness);
}

}  // namespace crumple::narrow
