#pragma once
/// \file
/// Internal: the k-DOP hierarchy behind `KdopTree` (kdop_tree.hpp), one class template per k,
/// whose members are defined in the units a reader finds by name:
///  - kdop_tree.cpp: parameters, the `KdopTree` facade, a frame's order of steps (`update`);
///  - kdop_build.cpp: patches, cuts, node layout (`build`);
///  - kdop_refit.cpp: bottom-up refit and the lanes' float k-DOPs (`refit`, `quality`);
///  - kdop_traversal.cpp: the parallel self-traversal (`traverse`);
///  - kdop_cache.cpp: the frame-to-frame cache of candidates (`choose_coherence`);
///  - kdop_cones.cpp: normal-cone culling of self-tests (`build_contours`, `normal_masks`).
/// Each unit instantiates its entry points for k = 6, 14, 18, 26; the hot loops are whole inside
/// one unit, so splitting them into files changes no inlining on their paths.

#include <crumple/detect/broad_phase/kdop_tree.hpp>
#include <crumple/geometry/kdop.hpp>

#include <algorithm>
#include <array>
#include <atomic>
#include <bit>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

namespace crumple {

/// Type-erased hierarchy: one implementation per k.
class KdopTree::Impl {
 public:
  virtual ~Impl() = default;
  virtual void update(const Topology& topo, const FrameInput& in, DetectorStats& stats) = 0;
  virtual void self_pairs(CandidateBuffer& out, DetectorStats& stats) = 0;
  virtual int levels() const = 0;
  virtual std::vector<Bounds> boxes(int depth) const = 0;
  virtual std::vector<std::vector<Index>> leaf_faces() const = 0;
};

namespace detail {

/// Members per lane group: eight floats / eight lane masks (GCC and Clang vector extensions:
/// one AVX register, or two SSE ones on x86-64 where the traversal's clone without AVX2 runs;
/// NEON pairs on Arm).
constexpr int kGroup = 8;
using F8 = float __attribute__((vector_size(4 * kGroup)));
using I8 = std::int32_t __attribute__((vector_size(4 * kGroup)));
using F4 = float __attribute__((vector_size(16)));

/// The traversal's recursive functions and the refit's loop are compiled three times, for
/// x86-64-v4 (AVX-512: the lane comparisons into mask registers), with AVX2 (a lane group in
/// one register) and without, and the CPU picks at load time (GCC's function multiversioning).
/// The library is built with -ffp-contract=off (src/CMakeLists.txt), so that the v4 clone,
/// whose target has FMA, rounds as the others do. Under the sanitizers, one clone: the same
/// source, a third of the compile time of kdop_traversal.cpp and kdop_refit.cpp.
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__) && !defined(CRUMPLE_SANITIZED)
#define CRUMPLE_SIMD_CLONES __attribute__((target_clones("arch=x86-64-v4", "avx2", "default")))
#else
#define CRUMPLE_SIMD_CLONES
#endif

/// The k-DOP hierarchy for one k (kdop_tree.hpp's file comment describes the method).
template <int K>
class DopTree final : public KdopTree::Impl {
  using Dop = geometry::Kdop<K>;
  static constexpr int kAxes = Dop::kAxes;
  /// Up to eight k-DOPs of a node's members (an internal node's children, a leaf's faces) side
  /// by side, one lane each, in float (`to_float`), so that a k-DOP is tested against eight
  /// members with a few vector compares (no branch per slab). Unused lanes are empty (min +inf,
  /// max -inf). Conservative: k-DOPs that overlap in double always overlap here; the face
  /// pairs that pass are then tested in double.
  struct alignas(32) Lanes {
    std::array<F8, kAxes> lo, hi;
  };
  /// A node's or face's k-DOP in float (the query side of a lane test).
  struct FloatDop {
    std::array<float, kAxes> lo, hi;
  };

  /// Temporal coherence (proximity queries, `coherence=on`). A refresh frame inflates every
  /// k-DOP by kSlack times the radius more and records the candidates of each *unit*: the first
  /// self-test of a node of at most kUnitFaces faces, or pair test of two such nodes, that the
  /// traversal reaches (the same units whatever the thread count: tasks are never cut inside
  /// one). A later frame gives each node the box of its vertices' displacements since the
  /// refresh; a unit whose displacements differ by at most the slack s = 2 (refresh radius -
  /// radius) emits the recorded candidates instead of being traversed. Exact: two points of
  /// its faces within the padded thickness now were within it + s on the refresh frame (their
  /// relative position changed by at most s), so their faces' k-DOPs, inflated by half of
  /// that, overlapped then, and the pair was recorded (a unit with no record had none).
  static constexpr Index kUnitFaces = 512;
  static constexpr Scalar kSlack = 1.0 / 16;
  enum class Mode { off, record, reuse };
  /// A recorded unit: candidates unit_pairs_[begin, end) of the nodes key = (min << 32 | max).
  struct Unit {
    std::uint64_t key;
    std::size_t begin, end;
  };
  /// One task's traversal state.
  struct Walk {
    std::vector<FacePair> out;
    std::vector<Unit> units;  ///< refresh frames: its units with candidates, into `pairs`
    std::vector<FacePair> pairs;
    std::size_t reused = 0, live = 0;
    /// Fine streaming (a consumer that asks for chunk size below kFineChunk: a cut-off frame,
    /// exact_detector.hpp): `out` is handed to it every kFineChunk candidates inside a task,
    /// and the walk stops as soon as it has asked the buffer to stop, so that a budget is
    /// looked at every few dozen candidates rather than once per task (a task may be a whole
    /// coherence unit of kUnitFaces faces). Null otherwise.
    CandidateBuffer* fine = nullptr;
    bool stopped = false;  ///< fine streaming: the consumer stopped; the task is left unfinished
    unsigned visits = 0;   ///< fine streaming: node visits, the buffer polled every kPollVisits
    /// Recording a unit (refresh frames): its candidates start at out[unit_from]; those handed
    /// over before are already in `pairs`. kNoUnit outside a recorded unit.
    std::size_t unit_from = kNoUnit;
  };
  static constexpr std::size_t kNoUnit = ~std::size_t{0};
  /// Fine streaming: candidates per hand-over inside a task (the cut-off claims blocks of 64).
  static constexpr std::size_t kFineChunk = 64;
  /// Fine streaming: node visits between two polls of the buffer (`CandidateBuffer::poll`),
  /// for the stretches of the traversal that find no candidate.
  static constexpr unsigned kPollVisits = 16;

  /// Leaf: `first`/`count` index slots of `order_`; internal: child node ids.
  struct Node {
    Index first = 0;
    Index count = 0;
    Index faces = 0;  ///< faces below the node
    bool leaf = false;
    Index slot_begin = 0, slot_end = 0;  ///< the node's faces: slots [slot_begin, slot_end)
    Index lanes = 0;  ///< members first + 8g .. first + 8g + 7 are in lanes_[lanes + g]
  };

  /// The members that a leaf's faces' lane tests found: face `slot[k]` against members `first +
  /// l` for the bits l of `members[k]` (not 0), `pairs` bits in all.
  struct Hits {
    std::array<std::uint64_t, 64> members;
    std::array<Index, 64> slot;
    std::size_t queries = 0, pairs = 0;
    void add(Index s, std::uint64_t m) {
      members[queries] = m;
      slot[queries] = s;
      queries += m != 0 ? 1u : 0u;
      pairs += static_cast<std::size_t>(std::popcount(m));
    }
  };

 public:
  explicit DopTree(const KdopParams& params) : params_(params) {}

  // kdop_tree.cpp
  void update(const Topology& topo, const FrameInput& in, DetectorStats& stats) override;
  void self_pairs(CandidateBuffer& out, DetectorStats& stats) override;
  int levels() const override { return static_cast<int>(levels_.size()); }
  std::vector<Bounds> boxes(int depth) const override;
  std::vector<std::vector<Index>> leaf_faces() const override;

 private:
  // ---- build (kdop_build.cpp) -----------------------------------------------------------------
  void build(const Topology& topo, PositionsView x, std::span<const std::uint8_t> owns, DetectorStats& stats);
  void connected_components(const Topology& topo, const std::vector<Vec3>& centroid);
  void cut_nodes(const std::vector<Vec3>& centroid, Index nf);
  void index_slots(const Topology& topo, std::span<const std::uint8_t> owns);
  void index_units();
  void grow_patches(const Topology& topo, const std::vector<Vec3>& centroid);
  void patch_centroids(const std::vector<Vec3>& centroid);
  int longest_axis(const std::vector<Vec3>& centroid, Index begin, Index end) const;
  void group_leaf(const std::vector<Vec3>& centroid, Index begin, Index end);
  void split(const std::vector<Vec3>& centroid, Index begin, Index end, Index parts, std::vector<Index>& cuts);
  Index component_cut(const std::vector<Vec3>& centroid, Index begin, Index end, Index mid, int longest);

  // ---- normal-cone culling (kdop_cones.cpp) ---------------------------------------------------
  static const std::array<Vec3, 26>& directions();
  void build_contours();
  void normal_masks(PositionsView x);
  /// Whether node n provably cannot intersect itself (`cone_culled`); false at once when this
  /// frame does not cull, without a call on the traversal's path.
  bool culled(Index n) const { return culling_ && cone_culled(n); }
  bool cone_culled(Index n) const;

  // ---- refit (kdop_refit.cpp) -----------------------------------------------------------------
  void refit(const FrameInput& in);
  CRUMPLE_SIMD_CLONES void refit_nodes(std::size_t first, std::size_t last, const FrameInput& in, bool swept,
                                       Scalar radius, bool moves);
  void prefetch_corners_ahead(std::span<const Vec3> x, Index s) const;
  Dop refit_leaf_lanes(const Node& node, const FrameInput& in, bool swept, Scalar radius, FloatDop* faces);
  Dop refit_leaf(const Node& node, const FrameInput& in, bool swept, Scalar radius, FloatDop* faces);
  Dop refit_leaf18(const Node& node, std::span<const Vec3> x, Scalar radius)
    requires(K == 18);
  static FloatDop float_dop(const Dop& d);
  void fill_lanes(const Node& node, const FloatDop* members);
  void empty_lanes_past_members(const Node& node);
  static Scalar extent(const Dop& d);
  double quality() const;

  // ---- traversal (kdop_traversal.cpp) ---------------------------------------------------------
  bool candidate(Index i, Index j) const;
  bool now_apart(Index i, Index j) const;
  std::uint64_t idle_with(Index n, Index i) const;
  FacePair pair_of(Index i, Index j) const;
  FloatDop member(const Node& node, Index i) const;
  CRUMPLE_SIMD_CLONES void emit_leaf_pair(Index ia, Index ib, std::vector<FacePair>& out) const;
  template <class Keep>
  void emit_hits(Hits& hits, Index first, const Keep& keep, std::vector<FacePair>& out) const;
  std::uint64_t overlapping_members(const Node& node, const FloatDop& f, std::uint64_t only = ~std::uint64_t{0},
                                    std::uint64_t tested = ~std::uint64_t{0}) const;
  std::uint64_t overlapping_node(const Node& node, Index q) const;
  template <bool kUnits>
  CRUMPLE_SIMD_CLONES void self(Index n, Walk& w) const;
  template <class F>
  void each_child_pair(const Node& node, const F& f) const;
  template <class F>
  void each_descent(Index a, Index b, const F& f) const;
  template <bool kUnits>
  CRUMPLE_SIMD_CLONES void pair(Index a, Index b, Walk& w) const;
  CRUMPLE_SIMD_CLONES void unit(Index a, Index b, Walk& w) const;
  void hand_over(Walk& w) const;
  bool halted(Walk& w) const;
  void traverse(int threads, CandidateBuffer& out, DetectorStats& stats);

  // ---- temporal coherence (kdop_cache.cpp) ----------------------------------------------------
  void choose_coherence(const FrameInput& in);
  void start_record(const FrameInput& in);
  bool cache_fresh(PositionsView x) const;
  /// Bound on |(p - p_ref) - (q - q_ref)| for points p, q of the faces of two nodes with these
  /// displacement boxes (a point of a face moves by a convex combination of its corners'
  /// displacements, which lies in the box), with the rounding of x - x_ref (relative to the
  /// displacement) and of the norm covered. Reuse frames have finite positions (checked).
  /// Inline: the traversal calls it once per unit.
  static Scalar spread(const Box& a, const Box& b) {
    Box u = a;
    u.merge(b);
    Scalar s2 = 0, big = 0;
    for (std::size_t k = 0; k < 3; ++k) {
      s2 += (u.hi[k] - u.lo[k]) * (u.hi[k] - u.lo[k]);
      big = std::max({big, std::abs(u.lo[k]), std::abs(u.hi[k])});
    }
    return std::sqrt(s2) * (1 + 1e-12) + 1e-12 * big;
  }

  const KdopParams& params_;
  std::size_t resume_ = 0;  ///< the first task a stopped traversal left out (`CandidateBuffer::resuming`)
  // Temporal coherence (proximity frames).
  Mode mode_ = Mode::off;
  Scalar refit_radius_ = 0;  ///< this frame's inflation radius
  bool cache_valid_ = false;  ///< units_ hold a complete refresh frame of the current tree
  bool cache_refreshed_ = false;  ///< the previous frame recorded
  int cache_backoff_ = 0, cache_wait_ = 0;
  Scalar cache_radius_ = 0;  ///< inflation radius of the refresh frame
  Scalar slack_ = 0;         ///< 2 (cache_radius_ - this frame's radius)
  Positions cache_ref_;      ///< positions of the refresh frame
  std::vector<Unit> units_;  ///< the refresh frame's units with candidates, by key
  std::vector<FacePair> unit_pairs_;
  std::vector<Box> moved_;  ///< per node, reuse frames: box of the displacements since the refresh
  std::vector<char> small_;   ///< per node: at most kUnitFaces faces
  std::vector<Index> leaf_ids_;
  std::vector<std::size_t> leaf_verts_;  ///< per node: a leaf's vertices are verts_[n, n + 1)
  std::vector<Index> verts_;
  // The leaves to be, grown at the first build and kept (`grow_patches`).
  std::vector<Index> patch_;  ///< per face, its patch
  std::size_t patches_ = 0;   ///< patch ids are below this
  // Scratch of `build` and `split`, released after the cuts.
  std::vector<Index> component_;          ///< per face, its connected component
  std::vector<Vec3> patch_centroid_;      ///< per patch, mean face centroid
  std::vector<Vec3> component_centroid_;  ///< per component id, mean face centroid
  std::vector<Index> component_faces_;    ///< per component id (all 0 between uses)
  std::vector<Scalar> scratch_;
  std::vector<Node> nodes_;
  std::vector<Dop> dops_;
  std::vector<FloatDop> float_dops_;  ///< per node
  std::vector<Lanes> lanes_;          ///< per node, its members (children or faces) eight to a group
  std::vector<Index> order_;     ///< face of each leaf slot
  std::vector<Face> slot_faces_;  ///< corners of each slot's face (adjacency test locality)
  std::vector<std::uint8_t> slot_owns_;        ///< per slot, FrameInput::owns (proximity queries)
  std::vector<std::uint64_t> leaf_no_vertex_;  ///< per leaf: bit j, member j owns no vertex
  std::vector<std::uint64_t> leaf_no_edge_;    ///< per leaf: bit j, member j owns no edge
  std::vector<std::uint64_t> leaf_adjacent_;  ///< per slot: bit j, member j of its leaf shares a vertex
  std::vector<Dop> now_dops_;     ///< per slot, current positions only, inflated (when swept)
  bool swept_ = false;            ///< this frame's boxes cover the motion
  std::vector<std::array<Index, 2>> levels_;  ///< node range of each depth
  std::vector<Index> level_leaf_faces_;       ///< faces in the leaves of each depth
  double built_quality_ = 0;
  // Normal-cone culling (intersection-only frames).
  bool culling_ = false;
  bool contours_valid_ = false;
  std::vector<Index> contour_offsets_;             ///< per node, into contour_edges_
  std::vector<std::array<Index, 2>> contour_edges_;  ///< directed boundary edges (vertex ids)
  std::vector<char> cullable_;                     ///< per node: consistently oriented, manifold
  std::vector<std::uint32_t> face_masks_, node_masks_;
  PositionsView positions_;
  int threads_ = 0;  ///< of the last update
  mutable std::atomic<long long> culled_{0};
};

/// Calls X(6) X(14) X(18) X(26): each unit instantiates its entry points for every k.
#define CRUMPLE_KDOP_FOR_EACH_K(X) X(6) X(14) X(18) X(26)

}  // namespace detail
}  // namespace crumple
