#pragma once
/// \file
/// The narrow phase shared by every detector: one function per primitive pair that applies the
/// contact definition (detector.hpp) with the geometry kernels and fills a typed contact. Every
/// detector calls these, so distances are bit-identical across methods. Topological exclusion
/// (adjacent pairs) is the caller's job: these functions assume a non-adjacent pair.

#include <crumple/core/types.hpp>
#include <crumple/detect/contact.hpp>
#include <crumple/geometry/distance.hpp>
#include <crumple/geometry/kernel_batch.hpp>
#include <crumple/geometry/triangle_intersection.hpp>
#include <crumple/mesh/mesh.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <optional>
#include <vector>

namespace crumple::narrow {

inline const Vec3& at(PositionsView x, Index i) { return x[static_cast<std::size_t>(i)]; }

/// What squared distances are compared with (contact when below it) for thickness h: h^2, or,
/// when that underflows to 0 for h > 0, the smallest positive double, so that pairs at distance
/// 0 stay contacts (0 < h).
inline Scalar sqr_thickness(Scalar h) {
  const Scalar h2 = h * h;
  return h > 0 && h2 == 0 ? std::numeric_limits<Scalar>::denorm_min() : h2;
}

/// The normal of a vertex-face contact at distance 0: the geometric normal of the face with
/// corners a, b, c; zero if the face is degenerate.
inline Vec3 face_normal(const Vec3& a, const Vec3& b, const Vec3& c) {
  const Vec3 n = (b - a).cross(c - a);
  const Scalar len = n.norm();
  return len > 0 ? Vec3(n / len) : Vec3::Zero();
}

/// Vertex v at p against face f with corners a, b, c in face order (v not a corner of f); a
/// contact when the distance is < h (`sqr_thickness` = h^2). The normal points from the face to
/// the vertex. The squared distance, contact or not, goes to `*sqr_distance` when given.
inline std::optional<VertexFaceContact> vertex_face(Index v, const Vec3& p, Index f, const Vec3& a,
                                                    const Vec3& b, const Vec3& c, Scalar sqr_thickness,
                                                    Scalar* sqr_distance = nullptr) {
  const geometry::PointTriangleResult r = geometry::point_triangle(p, a, b, c);
  if (sqr_distance != nullptr) *sqr_distance = r.sqr_distance;
  if (!(r.sqr_distance < sqr_thickness)) return std::nullopt;
  const Vec3 away = p - r.closest;
  const Scalar away_norm = away.norm();
  return VertexFaceContact{v, f, std::sqrt(r.sqr_distance), r.barycentric,
                           away_norm > 0 ? Vec3(away / away_norm) : face_normal(a, b, c)};
}

/// Same, with the positions read from x.
inline std::optional<VertexFaceContact> vertex_face(PositionsView x, const Topology& topo, Index v,
                                                    Index f, Scalar sqr_thickness) {
  const Face& t = topo.face(f);
  return vertex_face(v, at(x, v), f, at(x, t[0]), at(x, t[1]), at(x, t[2]), sqr_thickness);
}

/// The normal of an edge-edge contact whose closest points coincide: the normalised cross
/// product of the directions of edges (p0, p1) and (q0, q1); zero if they are parallel.
inline Vec3 crossing_normal(const Vec3& p0, const Vec3& p1, const Vec3& q0, const Vec3& q1) {
  const Vec3 n = (p1 - p0).cross(q1 - q0);
  const Scalar len = n.norm();
  return len > 0 ? Vec3(n / len) : Vec3::Zero();
}

/// The contact of edges e0 = ea and e1 = eb (at p0, p1 and q0, q1, as `edge_edge` takes them)
/// from their kernel result r (segment_segment(p0, p1, q0, q1), closest points included), whose
/// distance the caller found below h.
inline EdgeEdgeContact edge_edge_contact(Index e0, const Edge& ea, const Vec3& p0, const Vec3& p1, Index e1,
                                         const Edge& eb, const Vec3& q0, const Vec3& q1,
                                         const geometry::SegmentSegmentResult& r) {
  const Vec3 gap = r.closest1 - r.closest0;
  const Scalar gap_norm = gap.norm();
  const Vec3 normal = gap_norm > 0 ? Vec3(gap / gap_norm) : crossing_normal(p0, p1, q0, q1);
  return make_edge_edge_contact(e0, ea, e1, eb, std::sqrt(r.sqr_distance), r.s, r.t, normal);
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
  return edge_edge_contact(e0, ea, p0, p1, e1, eb, q0, q1, r);
}

/// Edges e0 < e1 (sharing no vertex), with the positions read from x.
inline std::optional<EdgeEdgeContact> edge_edge(PositionsView x, const Topology& topo, Index e0,
                                                Index e1, Scalar sqr_thickness) {
  const Edge& ea = topo.edge(e0);
  const Edge& eb = topo.edge(e1);
  return edge_edge(e0, ea, at(x, ea[0]), at(x, ea[1]), e1, eb, at(x, eb[0]), at(x, eb[1]), sqr_thickness);
}

/// An edge pair as `edge_edge` takes it (e0 < e1, each edge as the mesh stores it, p0 p1 the
/// positions of ea's vertices, q0 q1 eb's), from edges given in any order: edge e of vertices
/// (u0, u1) at (x0, x1) and edge f of vertices (w0, w1) at (y0, y1).
struct EdgePair {
  Index e0, e1;
  Edge ea, eb;
  const Vec3 *p0, *p1, *q0, *q1;
  static EdgePair ordered(Index e, Index u0, Index u1, const Vec3& x0, const Vec3& x1, Index f, Index w0, Index w1,
                          const Vec3& y0, const Vec3& y1) {
    EdgePair pair;
    pair.set(e, u0, u1, x0, x1, f, w0, w1, y0, y1);
    return pair;
  }
  /// Makes this pair `ordered(e, u0, ...)`, field by field (`EdgeEdgeBatch::push` fills its
  /// queue's slot so: a pair built first and then copied was read back with 16-byte loads from
  /// its 4-byte stores, a failed store forwarding on every push). Every choice is a select by a
  /// mask, without a branch: which way round the edges come is unpredictable, and std::min's
  /// and std::max's references, the choice of a whole Edge and even `c ? &x0 : &x1` compiled to
  /// branches (a tenth of armadillo's frame's branch mispredictions).
  void set(Index e, Index u0, Index u1, const Vec3& x0, const Vec3& x1, Index f, Index w0, Index w1, const Vec3& y0,
           const Vec3& y1) {
    const auto mask = [](bool c) { return std::uintptr_t{0} - static_cast<std::uintptr_t>(c); };
    const auto pick = [](std::uintptr_t m, const Vec3* t, const Vec3* f) {
      return reinterpret_cast<const Vec3*>((reinterpret_cast<std::uintptr_t>(t) & m) |
                                           (reinterpret_cast<std::uintptr_t>(f) & ~m));
    };
    const auto pick_index = [](std::uintptr_t m, Index t, Index f) {
      return static_cast<Index>(static_cast<std::uint32_t>((static_cast<std::uint32_t>(t) & m) |
                                                           (static_cast<std::uint32_t>(f) & ~m)));
    };
    const std::uintptr_t up = mask(u0 < u1), wp = mask(w0 < w1), first = mask(e < f);
    const Index a_lo = pick_index(up, u0, u1), a_hi = pick_index(up, u1, u0);
    const Index b_lo = pick_index(wp, w0, w1), b_hi = pick_index(wp, w1, w0);
    const Vec3* a0 = pick(up, &x0, &x1);
    const Vec3* a1 = pick(up, &x1, &x0);
    const Vec3* b0 = pick(wp, &y0, &y1);
    const Vec3* b1 = pick(wp, &y1, &y0);
    e0 = pick_index(first, e, f);
    e1 = pick_index(first, f, e);
    ea = {pick_index(first, a_lo, b_lo), pick_index(first, a_hi, b_hi)};
    eb = {pick_index(first, b_lo, a_lo), pick_index(first, b_hi, a_hi)};
    p0 = pick(first, a0, b0);
    p1 = pick(first, a1, b1);
    q0 = pick(first, b0, a0);
    q1 = pick(first, b1, a1);
  }
  /// Makes this pair from edges already as `edge_edge` takes them (e < f, each as the mesh
  /// stores it, x0 x1 the positions of a's vertices, y0 y1 b's): nothing to choose.
  void set_in_order(Index e, const Edge& a, const Vec3& x0, const Vec3& x1, Index f, const Edge& b, const Vec3& y0,
                    const Vec3& y1) {
    e0 = e;
    e1 = f;
    ea = a;
    eb = b;
    p0 = &x0;
    p1 = &x1;
    q0 = &y0;
    q1 = &y1;
  }
  /// edge_edge on this pair.
  std::optional<EdgeEdgeContact> test(Scalar sqr_thickness, Scalar* sqr_distance = nullptr) const {
    return edge_edge(e0, ea, *p0, *p1, e1, eb, *q0, *q1, sqr_thickness, sqr_distance);
  }
};

/// Edge pairs tested four at a time (geometry::segment_segment_x4, the same bits as
/// `edge_edge`): `push` queues a pair, whose positions must stay in place until the next
/// `flush`; every fourth push, and `flush`, appends the contacts of the queued pairs to `out`.
/// Without AVX2 (`geometry::has_avx2()`), `push` tests each pair at once with `edge_edge`.
class EdgeEdgeBatch {
 public:
  /// Queues edge e of vertices (u0, u1) at (x0, x1) and edge f of vertices (w0, w1) at (y0, y1),
  /// in any order, as `EdgePair::ordered(e, u0, u1, x0, x1, f, w0, w1, y0, y1)` makes them.
  void push(Index e, Index u0, Index u1, const Vec3& x0, const Vec3& x1, Index f, Index w0, Index w1,
            const Vec3& y0, const Vec3& y1, Scalar sqr_thickness, std::vector<EdgeEdgeContact>& out) {
    queue([&](EdgePair& pair) { pair.set(e, u0, u1, x0, x1, f, w0, w1, y0, y1); }, sqr_thickness, out);
  }
  /// Queues a pair already as `edge_edge` takes it (`EdgePair::set_in_order`): the orphans'
  /// pairs, whose order `set`'s selects would only find again.
  void push_in_order(Index e, const Edge& a, const Vec3& x0, const Vec3& x1, Index f, const Edge& b,
                     const Vec3& y0, const Vec3& y1, Scalar sqr_thickness, std::vector<EdgeEdgeContact>& out) {
    queue([&](EdgePair& pair) { pair.set_in_order(e, a, x0, x1, f, b, y0, y1); }, sqr_thickness, out);
  }
  void flush(Scalar sqr_thickness, std::vector<EdgeEdgeContact>& out) {
    if (n_ == 0) return;
    const geometry::SegmentBatchResult r = geometry::segment_segment_x4(batch_);
    for (std::size_t i = 0; i < n_; ++i) {
      if (!(r.sqr_distance[i] < sqr_thickness)) continue;
      const EdgePair& p = pairs_[i];
      // The computations of edge_edge_contact, made in the lanes (the same bits).
      const Vec3 normal = r.gap_norm[i] > 0 ? Vec3(r.normal[0][i], r.normal[1][i], r.normal[2][i])
                                            : crossing_normal(*p.p0, *p.p1, *p.q0, *p.q1);
      out.push_back(make_edge_edge_contact(p.e0, p.ea, p.e1, p.eb, r.distance[i], r.s[i], r.t[i], normal));
    }
    n_ = 0;
  }

 private:
  /// Queues the pair that fill(pair) makes (tested at once without lanes).
  template <class Fill>
  void queue(const Fill& fill, Scalar sqr_thickness, std::vector<EdgeEdgeContact>& out) {
    if (!lanes_) {
      EdgePair pair;
      fill(pair);
      if (auto c = pair.test(sqr_thickness)) out.push_back(*c);
      return;
    }
    EdgePair& pair = pairs_[n_];
    fill(pair);
    batch_.set(n_++, *pair.p0, *pair.p1, *pair.q0, *pair.q1);
    if (n_ == geometry::SegmentBatch::kLanes) flush(sqr_thickness, out);
  }

  bool lanes_ = geometry::has_avx2();
  geometry::SegmentBatch batch_;
  std::array<EdgePair, geometry::SegmentBatch::kLanes> pairs_{};
  std::size_t n_ = 0;
};

/// Vertex-face pairs tested four at a time (geometry::point_triangle_x4, the same bits as
/// `vertex_face`): `push` queues a pair, whose positions must stay in place until the next
/// `flush`; every fourth push, and `flush`, appends the contacts of the queued pairs to `out`.
/// Without AVX2 (`geometry::has_avx2()`), `push` tests each pair at once with `vertex_face`.
class VertexFaceBatch {
 public:
  /// Vertex v at p against face f with corners a, b, c, as `vertex_face` takes them.
  void push(Index v, const Vec3& p, Index f, const Vec3& a, const Vec3& b, const Vec3& c, Scalar sqr_thickness,
            std::vector<VertexFaceContact>& out) {
    if (!lanes_) {
      if (auto contact = vertex_face(v, p, f, a, b, c, sqr_thickness)) out.push_back(*contact);
      return;
    }
    batch_.set(n_, p, a, b, c);
    pairs_[n_++] = {v, f, &a, &b, &c};
    if (n_ == geometry::PointTriangleBatch::kLanes) flush(sqr_thickness, out);
  }
  void flush(Scalar sqr_thickness, std::vector<VertexFaceContact>& out) {
    if (n_ == 0) return;
    const geometry::PointTriangleBatchResult r = geometry::point_triangle_x4(batch_);
    for (std::size_t i = 0; i < n_; ++i) {
      if (!(r.sqr_distance[i] < sqr_thickness)) continue;
      const Pair& p = pairs_[i];
      // The computations of vertex_face, made in the lanes (the same bits).
      const Vec3 normal = r.away_norm[i] > 0 ? Vec3(r.normal[0][i], r.normal[1][i], r.normal[2][i])
                                             : face_normal(*p.a, *p.b, *p.c);
      out.push_back(VertexFaceContact{p.v, p.f, r.distance[i],
                                      Vec3(r.barycentric[0][i], r.barycentric[1][i], r.barycentric[2][i]), normal});
    }
    n_ = 0;
  }

 private:
  struct Pair {
    Index v, f;
    const Vec3 *a, *b, *c;
  };
  bool lanes_ = geometry::has_avx2();
  geometry::PointTriangleBatch batch_;
  std::array<Pair, geometry::PointTriangleBatch::kLanes> pairs_{};
  std::size_t n_ = 0;
};

/// Face pairs tested for intersection four at a time (geometry::triangles_intersect_x4, exact,
/// so the answers of `triangles_intersect`): `push` queues faces f < g, whose corners need not
/// stay in place; every fourth push, and `flush`, appends the intersecting pairs to `out`.
/// Without AVX2 (`geometry::has_avx2()`), `push` tests each pair at once.
class TriangleTriangleBatch {
 public:
  void push(Index f, const std::array<Vec3, 3>& a, Index g, const std::array<Vec3, 3>& b,
            std::vector<TriangleTriangleContact>& out) {
    if (!lanes_) {
      if (geometry::triangles_intersect(a[0], a[1], a[2], b[0], b[1], b[2])) out.push_back({f, g});
      return;
    }
    batch_.set(n_, a[0], a[1], a[2], b[0], b[1], b[2]);
    pairs_[n_++] = {f, g};
    if (n_ == geometry::TrianglePairBatch::kLanes) flush(out);
  }
  void flush(std::vector<TriangleTriangleContact>& out) {
    if (n_ == 0) return;
    const unsigned hits = geometry::triangles_intersect_x4(batch_, n_);
    for (std::size_t i = 0; i < n_; ++i) {
      if ((hits >> i & 1u) != 0) out.push_back(pairs_[i]);
    }
    n_ = 0;
  }

 private:
  bool lanes_ = geometry::has_avx2();
  geometry::TrianglePairBatch batch_;
  std::array<TriangleTriangleContact, geometry::TrianglePairBatch::kLanes> pairs_{};
  std::size_t n_ = 0;
};

}  // namespace crumple::narrow
