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

struct Orphans {
  /// (vertex, face) sub-pairs, by face (then vertex). No two the same (a feature has one owner,
  /// so a sub-pair comes from one pair of faces).
  std::vector<std::array<Index, 2>> vf;
  /// Edge pairs, by first edge (then second).
  std::vector<OrphanEdges> ee;
  OrphanBlocks vf_blocks, ee_blocks;
};

/// The orphan sub-pairs of `topo` under `own`, sorted and cut into blocks (every block awake,
/// with bound 0).
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
