#pragma once
/// \file
/// `kdop`: an inflated, motion-oriented k-DOP hierarchy over the faces (docs/exact-detectors.md;
/// Klosowski et al. 1998; Mezger, Kimmerle & Etzmuss 2003; Blender's kdop.c), a broad phase
/// (broad_phase.hpp) of the exact detector.
///
///  - Build (first frame, and again when the quality metric degrades): first the faces are
///    cut into connected patches of at most `leaf` faces (grown from seeds in Morton order, the
///    nearest faces first; small ones joined to a neighbour; at the first build only, a rebuild
///    keeps them), the leaves to be, which stay compact however the surface moves. Then
///    top-down, the faces sorted by their patch's centroid along the largest extent and cut
///    into `arity` near-equal parts at patch boundaries, down to nodes of one patch, the leaves
///    (their faces ordered so that each lane group of eight is a compact piece); where a node
///    holds several connected components, each of at most 512 faces, the cut goes between
///    components (ordered by their centroids, along the axis where this moves the fewest faces
///    across the median cut, at most a quarter) when that leaves each side at least a quarter
///    of the faces, so that small bodies that move apart are not mixed in a node. Nodes are
///    stored breadth-first, so every depth is one index range.
///  - Refit (every frame), bottom-up and level by level in parallel: a face's k-DOP holds its
///    corners at the current positions and, with `sweep=on` and previous positions given, at
///    the previous ones (the projection of a linearly moving point is linear in time, so this
///    bounds the whole motion: oriented inflation along the displacement), grown by half the
///    padded thickness along the unit directions. Swept leaf pairs are also checked with the
///    faces' boxes at the current positions, where the contacts are.
///  - Quality: the sum over nodes of the three coordinate extents, relative to the root's, is
///    recorded at build; when a refit makes it exceed `rebuild` times that value, the tree is
///    rebuilt from the current positions (counted in the `rebuilds` stat).
///  - Self-traversal (node against itself, then its children pairwise; descend the larger of
///    two overlapping nodes), expanded into many independent tasks run in parallel. A k-DOP is
///    tested against eight of a node's members (children, or a leaf's faces) at once, in float
///    (a monotone conversion, so never less than the double test keeps; one AVX register where
///    the CPU has AVX2, the traversal being compiled with and without it); face pairs that pass
///    are tested in double. Faces that share a vertex are skipped at the leaves (their orphan
///    sub-pairs are handled by the pipeline), and so, in a proximity query, are the pairs that
///    own no sub-pair (`FrameInput::owns`), by two masks per leaf.
/// Spec: `kdop:k=6|14|18|26,arity=2|4|8,leaf=N,rebuild=R,sweep=on|off,cones=on|off,coherence=on|off`
/// plus `max_contacts`, `overflow`.
///  - Normal-cone culling (Volino & Magnenat-Thalmann), for intersection-only
///    queries (`kinds` = tt): a node whose faces all face one of 26 fixed directions V (a
///    per-face bit mask ANDed up the tree) and whose boundary, projected along V, is one
///    star-shaped loop traversed once, projects one-to-one onto the plane, so no two of its
///    points coincide: its self-test is skipped. Proximity (vf, ee) is never culled: a patch that
///    is a height field can still hold features closer than the thickness. Needs consistently
///    oriented faces; any doubt (degenerate face, an edge used twice in one direction, a loop
///    winding more than once) keeps the self-test.
///  - Temporal coherence (`coherence=on`, proximity queries): a refresh frame inflates the
///    k-DOPs by a slack s more and records the candidates of each unit (the first self-test of a
///    node of at most 512 faces, or pair test of two such nodes, that the traversal reaches); on
///    later frames a unit whose vertices' displacements since then differ by at most s emits
///    those candidates without being traversed. Exact (the argument is in kdop_tree_detail.hpp). When
///    more than a quarter of a sample of leaves have moved beyond s the cache is refreshed, and
///    when that happens right after a refresh it waits 1, 2, 4, ... 64 frames (deforming cloth
///    pays only the sample).

#include <crumple/detect/broad_phase/broad_phase.hpp>

#include <memory>
#include <vector>

namespace crumple {

/// Parameters of the k-DOP hierarchy.
struct KdopParams {
  int k = 18;            ///< 6, 14, 18 or 26 directions
  int arity = 4;         ///< children per internal node: 2, 4 or 8
  int leaf = 48;         ///< maximum faces per leaf (1..64)
  double rebuild = 2.0;  ///< rebuild when the quality metric grows past this factor (>= 1)
  /// The hierarchy covers the motion from the previous positions (when given): the thesis'
  /// motion-oriented inflation. The contact set is the same either way (contacts are proximity
  /// at the current positions, and leaf pairs are also checked with boxes of the current
  /// positions), so it only costs traversal time; off by default (docs/exact-detectors.md).
  /// A continuous query (`FrameInput::continuous`, detect/continuous.hpp) always sweeps and
  /// keeps every pair whose swept k-DOPs overlap.
  bool sweep = false;
  /// Normal-cone culling of self-tests for intersection-only queries (see the file comment).
  /// Off by default: on the real meshes it skips few candidates and costs more
  /// than it saves (docs/exact-detectors.md).
  bool cones = false;
  /// Temporal coherence of the self-traversal for proximity queries (see the file comment):
  /// a patch (or a pair of nearby patches) whose vertices all moved by nearly the same vector
  /// since a refresh frame reuses that frame's candidates instead of being traversed again
  /// (rigid bodies carried along, cloth at rest). The contacts are the same either way.
  bool coherence = true;
  /// Reads a `kdop:...` spec; keys left out keep the defaults above.
  static KdopParams from_spec(const MethodSpec& spec);
  bool operator==(const KdopParams&) const = default;
  /// Throws `InputError` ("<who>: leaf must be in 1..64, got 65", ...) when a field is out of
  /// its range: a node's members are bits of one 64-bit mask.
  void validate(const std::string& who) const;
};

/// The k-DOP hierarchy as a broad phase; also the detector's `hierarchy()` view.
class KdopTree final : public BroadPhase, public BoundingHierarchy {
 public:
  /// Throws `InputError` when a parameter is out of range (`KdopParams::validate`).
  explicit KdopTree(KdopParams params);
  ~KdopTree() override;
  Method method() const override { return Method::Kdop; }
  const KdopParams& params() const { return params_; }
  void build(const Topology& topology) override;
  void update(const FrameInput& in, DetectorStats& stats) override;
  void self_pairs(CandidateBuffer& out, DetectorStats& stats) override;
  const BoundingHierarchy* hierarchy() const override { return this; }

  int levels() const override;
  /// The x, y, z slabs of the nodes' k-DOPs.
  std::vector<Bounds> node_boxes(int depth) const override;
  std::vector<std::vector<Index>> leaf_faces() const override;

  /// Type-erased tree (one implementation per k).
  class Impl;

 private:
  KdopParams params_;
  const Topology* topo_ = nullptr;
  std::unique_ptr<Impl> tree_;
};

}  // namespace crumple
