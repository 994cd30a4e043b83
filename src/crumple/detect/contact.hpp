#pragma once
/// \file
/// Contacts: what a narrow phase emits and a response consumes (distinct from broad-phase
/// candidates). One `ContactSet` per frame holds typed vectors, filled by one detector call.

#include <crumple/core/types.hpp>

#include <cstddef>
#include <filesystem>
#include <ostream>
#include <tuple>
#include <vector>

namespace crumple {

/// Vertex closer than the thickness to a face it is not a corner of. Aligned to its size (64
/// bytes, a cache line): a record read out of order, as the exact detectors' final gather
/// reads them, then costs one line instead of two.
struct alignas(64) VertexFaceContact {
  Index vertex = -1;
  Index face = -1;
  Scalar distance = 0;  ///< Euclidean distance from the vertex to the closest point of the face
  Vec3 barycentric = Vec3::Zero();  ///< of the closest point, w.r.t. the face's corners in order
  /// Unit vector from the closest point on the face towards the vertex; when the distance is 0,
  /// the face's geometric normal (or zero for a degenerate face).
  Vec3 normal = Vec3::Zero();
};

static_assert(sizeof(VertexFaceContact) == 64, "the alignment must not pad the record");

/// Two edges, sharing no vertex, closer than the thickness. `a` is the edge with the smaller
/// (first vertex, second vertex) pair; each edge's vertices are increasing (mesh edge order).
struct EdgeEdgeContact {
  Index edge0 = -1;  ///< mesh edge id of `a`
  Index edge1 = -1;  ///< mesh edge id of `b`
  Edge a{-1, -1};
  Edge b{-1, -1};
  Scalar distance = 0;
  Scalar s = 0;  ///< closest point on a: (1-s) x[a0] + s x[a1]
  Scalar t = 0;  ///< closest point on b: (1-t) x[b0] + t x[b1]
  /// Unit vector from the closest point on a towards the one on b; when the distance is 0,
  /// the normalised cross product of the edge directions (or zero if parallel).
  Vec3 normal = Vec3::Zero();
};

/// Two faces, sharing no vertex, that intersect (closed triangles). `face0 < face1`.
struct TriangleTriangleContact {
  Index face0 = -1;
  Index face1 = -1;
};

/// Which contact kinds a detector reports.
struct ContactKinds {
  bool vf = true;
  bool ee = true;
  bool tt = false;
  /// Parses a comma-separated list of `vf`, `ee`, `tt` (e.g. "vf,ee"); throws InputError.
  static ContactKinds parse(std::string_view list);
  std::string to_string() const;
};

/// The canonical order of contacts: VF by (vertex, face), EE by (a, b) vertex ids, TT by
/// (face0, face1).
struct CanonicalLess {
  bool operator()(const VertexFaceContact& x, const VertexFaceContact& y) const {
    return std::tie(x.vertex, x.face) < std::tie(y.vertex, y.face);
  }
  bool operator()(const EdgeEdgeContact& x, const EdgeEdgeContact& y) const {
    return std::tie(x.a, x.b) < std::tie(y.a, y.b);
  }
  bool operator()(const TriangleTriangleContact& x, const TriangleTriangleContact& y) const {
    return std::tie(x.face0, x.face1) < std::tie(y.face0, y.face1);
  }
};

/// The contacts of one frame, in typed vectors.
struct ContactSet {
  std::vector<VertexFaceContact> vf;
  std::vector<EdgeEdgeContact> ee;
  std::vector<TriangleTriangleContact> tt;

  void clear() {
    vf.clear();
    ee.clear();
    tt.clear();
  }
  std::size_t size() const { return vf.size() + ee.size() + tt.size(); }
  bool empty() const { return size() == 0; }
  /// Sorts every vector into the canonical order (`CanonicalLess`); a vector already in order
  /// costs one pass. Detectors return sorted sets.
  void sort();
};

/// Writes the stable text format, one contact a line, in canonical order:
///   `vf <vertex> <face> <distance>`
///   `ee <a0> <a1> <b0> <b1> <distance>`   (a0<a1, b0<b1, (a0,a1) < (b0,b1))
///   `tt <face0> <face1>`                   (face0 < face1)
/// Distances are printed with 17 significant digits (round-trip exact). `set` must be sorted.
void write_contacts(std::ostream& out, const ContactSet& set);
/// Same, atomically to a file.
void write_contacts_file(const std::filesystem::path& path, const ContactSet& set);

/// Fills an edge–edge contact from two edges (order-normalised so that `a < b`). Inline: the
/// narrow phases call it for every edge–edge contact (hundreds of thousands a frame).
inline EdgeEdgeContact make_edge_edge_contact(Index edge0, const Edge& a, Index edge1, const Edge& b,
                                              Scalar distance, Scalar s, Scalar t, const Vec3& normal) {
  EdgeEdgeContact c;
  const bool swap = b < a;
  c.edge0 = swap ? edge1 : edge0;
  c.edge1 = swap ? edge0 : edge1;
  c.a = swap ? b : a;
  c.b = swap ? a : b;
  c.s = swap ? t : s;
  c.t = swap ? s : t;
  c.normal = swap ? Vec3(-normal) : normal;
  c.distance = distance;
  return c;
}

}  // namespace crumple
