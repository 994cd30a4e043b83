#pragma once
/// \file
/// The pair types of the stochastic engine (stochastic_engine.hpp): the contact sink, the frame
/// context and the traits (distance, neighbours, exclusion, classification) of the VV, EE, VF
/// and EF pair types. Internal header: shared by the stochastic and hybrid detectors, so that
/// both record contacts through the same narrow phase (bit-identical with `naive`).

#include <crumple/core/types.hpp>
#include <crumple/detect/contact.hpp>
#include <crumple/detect/narrow_phase.hpp>
#include <crumple/detect/stochastic.hpp>
#include <crumple/detect/stochastic_engine.hpp>
#include <crumple/geometry/distance.hpp>
#include <crumple/geometry/kdop.hpp>
#include <crumple/geometry/triangle_intersection.hpp>
#include <crumple/mesh/mesh.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <span>
#include <utility>
#include <vector>

namespace crumple::stochastic_detail {

inline const Vec3& at(PositionsView x, Index i) { return x[static_cast<std::size_t>(i)]; }

/// Collects the frame's contacts without duplicates, each from the shared narrow phase.
class Sink {
 public:
  void begin(const Topology& topo, PositionsView x, Scalar h2, ContactKinds kinds, ContactSet& out) {
    topo_ = &topo;
    x_ = x;
    h2_ = h2;
    kinds_ = kinds;
    out_ = &out;
    vf_.clear();
    ee_.clear();
    tt_.clear();
  }
  const ContactKinds& kinds() const { return kinds_; }

  /// Vertex v vs face f (v not a corner). True when they are in contact (recorded once).
  bool add_vf(Index v, Index f) {
    if (!kinds_.vf) return false;
    const std::uint64_t k = pair_key(v, f);
    if (vf_.contains(k)) return true;
    const auto c = narrow::vertex_face(x_, *topo_, v, f, h2_);
    if (!c) return false;
    vf_.insert(k, 0);
    out_->vf.push_back(*c);
    return true;
  }
  /// Edges e0, e1 (sharing no vertex), any order.
  bool add_ee(Index e0, Index e1) {
    if (!kinds_.ee) return false;
    if (e1 < e0) std::swap(e0, e1);  // the order the reference uses: bit-identical distances
    const std::uint64_t k = pair_key(e0, e1);
    if (ee_.contains(k)) return true;
    const auto c = narrow::edge_edge(x_, *topo_, e0, e1, h2_);
    if (!c) return false;
    ee_.insert(k, 0);
    out_->ee.push_back(*c);
    return true;
  }
  /// Faces f0, f1 (sharing no vertex), any order: exact intersection test.
  bool add_tt(Index f0, Index f1) {
    if (!kinds_.tt) return false;
    if (f1 < f0) std::swap(f0, f1);
    const std::uint64_t k = pair_key(f0, f1);
    if (tt_.contains(k)) return true;
    const Face& a = topo_->face(f0);
    const Face& b = topo_->face(f1);
    if (!geometry::triangles_intersect(at(x_, a[0]), at(x_, a[1]), at(x_, a[2]), at(x_, b[0]),
                                       at(x_, b[1]), at(x_, b[2]))) {
      return false;
    }
    tt_.insert(k, 0);
    out_->tt.push_back({f0, f1});
    return true;
  }

 private:
  const Topology* topo_ = nullptr;
  PositionsView x_;
  Scalar h2_ = 0;
  ContactKinds kinds_;
  ContactSet* out_ = nullptr;
  PairTable vf_, ee_, tt_;
};

struct Context;

/// Precise tests between the faces around two vertices (vertex variant, thesis §3.2.2.5
/// "convergence sur les sommets"), with an 18-DOP pre-test per face pair and per-frame caches
/// of face pairs and sub-pairs.
class ZoneTester {
 public:
  void reset(Index num_faces) {
    kdops_.assign(static_cast<std::size_t>(num_faces), {});
    kdop_gen_.assign(static_cast<std::size_t>(num_faces), 0);
    gen_ = 0;
  }
  void begin_frame() {
    if (++gen_ == 0) {
      std::fill(kdop_gen_.begin(), kdop_gen_.end(), 0);
      gen_ = 1;
    }
    face_pairs_.clear();
    vf_.clear();
    ee_.clear();
  }
  Verdict zone(Context& ctx, Index a, Index b);

 private:
  using Kdop = geometry::Kdop<18>;
  const Kdop& kdop(const Context& ctx, Index f);
  Scalar face_pair(Context& ctx, Index fa, Index fb);

  std::vector<Kdop> kdops_;
  std::vector<std::uint32_t> kdop_gen_;
  std::uint32_t gen_ = 0;
  PairTable face_pairs_, vf_, ee_;
};

/// What the traits see: the frame's geometry, thresholds, the contact sink and the zone tester.
struct Context {
  const Topology& topo;
  PositionsView x;
  Scalar h2;     ///< thickness^2: contact when the squared distance is < h2
  Scalar near;   ///< near distance
  Scalar near2;  ///< near distance^2
  Sink& sink;
  ZoneTester& zone;
  EngineStats& zone_stats;  ///< where zone tests count their work (the VV engine's extra stats)
};

inline Scalar segment_sqr(const Context& c, Index e0, Index e1) {
  const Edge& a = c.topo.edge(e0);
  const Edge& b = c.topo.edge(e1);
  return geometry::segment_segment(at(c.x, a[0]), at(c.x, a[1]), at(c.x, b[0]), at(c.x, b[1])).sqr_distance;
}

inline Scalar vertex_face_sqr(const Context& c, Index v, Index f) {
  const Face& t = c.topo.face(f);
  return geometry::point_triangle(at(c.x, v), at(c.x, t[0]), at(c.x, t[1]), at(c.x, t[2])).sqr_distance;
}

inline bool vertices_adjacent(const Topology& topo, Index a, Index b) {
  const auto ring = topo.vertex_vertices()[a];
  return std::binary_search(ring.begin(), ring.end(), b);
}

/// Vertex–vertex with the L1 distance (the vertex variant's convergence). Pairs of equal or
/// one-ring vertices are excluded so that walks do not slide onto trivially close pairs. A pair
/// is near / colliding according to the precise tests of its zone.
struct VVTraits {
  static constexpr PairType kType = PairType::VV;
  static constexpr bool kSymmetric = true;
  static constexpr bool kSideEffect = false;
  static Index count_a(const Topology& t) { return t.num_vertices(); }
  static Index count_b(const Topology& t) { return t.num_vertices(); }
  static std::span<const Index> neighbours_a(const Topology& t, Index v) { return t.vertex_vertices()[v]; }
  static std::span<const Index> neighbours_b(const Topology& t, Index v) { return t.vertex_vertices()[v]; }
  static bool excluded(const Topology& t, Index a, Index b) { return a == b || vertices_adjacent(t, a, b); }
  static Scalar distance(const Context& c, Index a, Index b) {
    const Vec3 d = at(c.x, a) - at(c.x, b);
    return std::abs(d.x()) + std::abs(d.y()) + std::abs(d.z());
  }
  static Verdict classify(Context& c, Index a, Index b, Scalar /*l1*/) { return c.zone.zone(c, a, b); }
};

struct EETraits {
  static constexpr PairType kType = PairType::EE;
  static constexpr bool kSymmetric = true;
  static constexpr bool kSideEffect = true;
  static Index count_a(const Topology& t) { return t.num_edges(); }
  static Index count_b(const Topology& t) { return t.num_edges(); }
  static std::span<const Index> neighbours_a(const Topology& t, Index e) { return t.edge_edges()[e]; }
  static std::span<const Index> neighbours_b(const Topology& t, Index e) { return t.edge_edges()[e]; }
  static bool excluded(const Topology& t, Index a, Index b) { return t.edges_adjacent(a, b); }
  /// Squared distance, computed with the smaller id first like the reference.
  static Scalar distance(const Context& c, Index a, Index b) {
    return a < b ? segment_sqr(c, a, b) : segment_sqr(c, b, a);
  }
  static Verdict classify(Context& c, Index a, Index b, Scalar d) {
    return {d < c.h2 && c.sink.add_ee(a, b), d <= c.near2};
  }
};

struct VFTraits {
  static constexpr PairType kType = PairType::VF;
  static constexpr bool kSymmetric = false;
  static constexpr bool kSideEffect = true;
  static Index count_a(const Topology& t) { return t.num_vertices(); }
  static Index count_b(const Topology& t) { return t.num_faces(); }
  static std::span<const Index> neighbours_a(const Topology& t, Index v) { return t.vertex_vertices()[v]; }
  static std::span<const Index> neighbours_b(const Topology& t, Index f) { return t.face_faces()[f]; }
  static bool excluded(const Topology& t, Index v, Index f) { return t.face_has_vertex(f, v); }
  static Scalar distance(const Context& c, Index v, Index f) { return vertex_face_sqr(c, v, f); }
  static Verdict classify(Context& c, Index v, Index f, Scalar d) {
    return {d < c.h2 && c.sink.add_vf(v, f), d <= c.near2};
  }
};

/// Edge–face: squared distance between a segment and a triangle (0 when they meet, else the
/// smallest of the endpoint–triangle and segment–side distances). A colliding pair records its
/// VF and EE sub-contacts and, when the edge meets the face, TT contacts of the edge's faces.
struct EFTraits {
  static constexpr PairType kType = PairType::EF;
  static constexpr bool kSymmetric = false;
  static constexpr bool kSideEffect = true;
  static Index count_a(const Topology& t) { return t.num_edges(); }
  static Index count_b(const Topology& t) { return t.num_faces(); }
  static std::span<const Index> neighbours_a(const Topology& t, Index e) { return t.edge_edges()[e]; }
  static std::span<const Index> neighbours_b(const Topology& t, Index f) { return t.face_faces()[f]; }
  static bool excluded(const Topology& t, Index e, Index f) {
    const Edge& ed = t.edge(e);
    return t.face_has_vertex(f, ed[0]) || t.face_has_vertex(f, ed[1]);
  }
  static Scalar distance(const Context& c, Index e, Index f) {
    const Edge& ed = c.topo.edge(e);
    const Face& t = c.topo.face(f);
    const Vec3 &p = at(c.x, ed[0]), &q = at(c.x, ed[1]);
    const Vec3 &t0 = at(c.x, t[0]), &t1 = at(c.x, t[1]), &t2 = at(c.x, t[2]);
    if (geometry::segment_triangle_intersect(p, q, t0, t1, t2)) return 0;
    Scalar d = std::min(geometry::point_triangle(p, t0, t1, t2).sqr_distance,
                        geometry::point_triangle(q, t0, t1, t2).sqr_distance);
    d = std::min(d, geometry::segment_segment(p, q, t0, t1).sqr_distance);
    d = std::min(d, geometry::segment_segment(p, q, t1, t2).sqr_distance);
    d = std::min(d, geometry::segment_segment(p, q, t2, t0).sqr_distance);
    return d;
  }
  static Verdict classify(Context& c, Index e, Index f, Scalar d) {
    const bool colliding = d < c.h2;
    if (colliding) {
      const Edge& ed = c.topo.edge(e);
      c.sink.add_vf(ed[0], f);
      c.sink.add_vf(ed[1], f);
      for (const Index side : c.topo.face_edges(f)) c.sink.add_ee(e, side);
      if (d == 0 && c.sink.kinds().tt) {
        for (const Index g : c.topo.edge_faces()[e]) {
          if (!c.topo.faces_adjacent(g, f)) c.sink.add_tt(g, f);
        }
      }
    }
    return {colliding, d <= c.near2};
  }
};


}  // namespace crumple::stochastic_detail
