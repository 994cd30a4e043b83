#pragma once
/// \file
/// Internal to the exact detector: the orphan sub-pairs (Tang et al.'s orphan sets). Pairs of
/// faces that share a vertex are never candidates of a broad phase; their vertex-face and
/// edge-edge sub-pairs that are *not* excluded by adjacency (the vertex opposite a shared edge,
/// edges around a shared vertex) and that the faces own (ownership.hpp) are listed once per
/// topology and tested every frame, in blocks that sleep while they provably hold no contact.

#include <crumple/core/types.hpp>
#include <crumple/detect/detector.hpp>
#include <crumple/detect/exact/ownership.hpp>
#include <crumple/mesh/mesh.hpp>

#include <algorithm>
#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace crumple::exact {

/// An orphan edge pair, first < second, with both edges' vertices (read without going
/// through the topology's edge list: the hot loop reads every pair every frame).
struct OrphanEdges {
  std::array<Index, 2> e;
  Edge a, b;
};

/// An orphan list cut into blocks of `kOrphanBlock` sub-pairs (the last one shorter), each with
/// the vertices its sub-pairs use and a lower bound of their distances at the positions of
/// the last refresh (`OrphanSleep::ref`).
inline constexpr std::size_t kOrphanBlock = 64;
struct OrphanBlocks {
  std::vector<std::size_t> begin;   ///< block b uses verts[begin[b], begin[b + 1])
  std::vector<Index> verts;         ///< sorted, distinct, per block
  std::vector<Scalar> bound;        ///< lower bound of the block's distances at the last refresh
  std::vector<std::uint8_t> awake;  ///< tested this frame
  /// Block b's sub-pairs are runs of one face (VF) or first edge (EE), of lengths
  /// runs[run_begin[b], run_begin[b + 1]): a run shares its box test's bounds.
  std::vector<std::size_t> run_begin;
  std::vector<std::uint8_t> runs;
  std::size_t size() const { return bound.size(); }
};

/// Vertices with more faces than this are *stars*: the pairs of faces around them are quadratic
/// in number, so their orphan sub-pairs are not listed but found each frame among the faces
/// that come close (`narrow_stars`), in time and memory near-linear in the valence.
inline constexpr std::size_t kStarValence = 64;

struct Orphans {
  /// (vertex, face) sub-pairs, by face (then vertex). No two the same (a feature has one owner,
  /// so a sub-pair comes from one pair of faces).
  std::vector<std::array<Index, 2>> vf;
  /// Edge pairs, by first edge (then second).
  std::vector<OrphanEdges> ee;
  OrphanBlocks vf_blocks, ee_blocks;
  /// The stars, ascending. A pair of faces is the orphan source of its smallest shared vertex:
  /// listed above when that vertex is not a star, found by `narrow_stars` when it is.
  std::vector<Index> stars;
};

/// The smallest vertex that faces f and g share (-1 if none).
inline Index smallest_shared_vertex(const Topology& topo, Index f, Index g) {
  Index smallest = -1;
  for (const Index u : topo.face(f)) {
    if (topo.face_has_vertex(g, u) && (smallest < 0 || u < smallest)) smallest = u;
  }
  return smallest;
}

/// Calls vf(vertex, face) and ee(first edge, second edge) for each orphan sub-pair of the
/// distinct faces f and g, which share a vertex: the owned vertices of one that the other does
/// not use against the other, and the owned edges of both that share no vertex (first <
/// second).
template <class VertexFace, class EdgeEdge>
void for_each_orphan(const Topology& topo, const FeatureOwnership& own, Index f, Index g, const VertexFace& vf,
                     const EdgeEdge& ee) {
  const Face& a = topo.face(f);
  const Face& b = topo.face(g);
  const auto& fa = topo.face_edges(f);
  const auto& fb = topo.face_edges(g);
  const unsigned vertex_f = own.vertex_mask[static_cast<std::size_t>(f)];
  const unsigned vertex_g = own.vertex_mask[static_cast<std::size_t>(g)];
  for (int k = 0; k < 3; ++k) {
    if ((vertex_f >> k & 1u) && !topo.face_has_vertex(g, a[k])) vf(a[k], g);
    if ((vertex_g >> k & 1u) && !topo.face_has_vertex(f, b[k])) vf(b[k], f);
  }
  const unsigned edge_f = own.edge_mask[static_cast<std::size_t>(f)];
  const unsigned edge_g = own.edge_mask[static_cast<std::size_t>(g)];
  for (int i = 0; i < 3; ++i) {
    if (!(edge_f >> i & 1u)) continue;
    for (int j = 0; j < 3; ++j) {
      if (!(edge_g >> j & 1u) || topo.edges_adjacent(fa[i], fb[j])) continue;
      ee(std::min(fa[i], fb[j]), std::max(fa[i], fb[j]));
    }
  }
}

/// The orphan sub-pairs of `topo` under `own` whose source is not a star, sorted and cut into
/// blocks (every block awake, with bound 0), and the stars.
Orphans list_orphans(const Topology& topo, const FeatureOwnership& own);

/// Temporal coherence of the orphans across frames.
struct OrphanSleep {
  Positions ref;           ///< positions of the last refresh; empty: none yet
  bool refreshed = false;  ///< the previous frame was a refresh
  int backoff = 0;         ///< frames to wait before the next refresh after one that did not pay
  int wait = 0;            ///< frames left to wait (every block tested meanwhile)
};

/// Marks the blocks to test this frame (`OrphanBlocks::awake`). A block whose vertices have
/// moved since the last refresh, relative to its first one, by less than half its bound's
/// margin over `pad` cannot hold a pair within `pad` and sleeps; every block is awake on a
/// refresh. Returns whether this frame is a refresh: then the caller's tests must set every
/// block's bound and the caller then stores `x` as `sleep.ref`. Sets `orphan_sampled`.
bool wake_orphan_blocks(Orphans& orphans, OrphanSleep& sleep, PositionsView x, Scalar pad, int threads,
                        DetectorStats& stats);

}  // namespace crumple::exact
