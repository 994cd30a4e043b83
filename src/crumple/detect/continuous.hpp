#pragma once
/// \file
/// Continuous collision detection (CCD) of a whole mesh over one step: every vertex moves
/// linearly, x(t) = x⁰ + t (x¹ − x⁰), t ∈ [0, 1], from `previous` to `current`. Reports every
/// vertex–face (VF) and edge–edge (EE) pair that comes within the minimum separation δ ≥ 0 at
/// some t, with a conservative time of impact (TOI), and the collision-free step.
///
/// Pipeline (docs/ccd.md): a broad phase (`kdop`, always swept; `hash`; `sap`) over face boxes
/// that cover each face's whole motion, grown by δ/2 and a rounding margin, streams candidate
/// face pairs in chunks to the narrow phase (geometry/ccd.hpp) on the broad phase's own
/// threads; each VF and EE sub-pair is tested in exactly one face pair (feature ownership), the
/// sub-pairs of faces sharing a vertex (orphans) and the vertices of no face are tested apart.
/// Pairs sharing a vertex are never tested.
///
/// Guarantees (those of geometry/ccd.hpp, per pair):
///  - No false negatives: every pair of a vertex and a face it is not a corner of, and of two
///    edges sharing no vertex, that comes within Euclidean distance δ at some t ∈ [0, 1] is
///    reported. The broad phase only drops pairs whose swept boxes (k-DOPs) are provably apart.
///  - `toi` is never later than the pair's first time within δ; `collision_free_step` is the
///    earliest of them, or 1.
///  - Deterministic: the same impacts, bit for bit, for every method, parameter and thread
///    count, sorted canonically.
///  - Memory: the candidates are never all held; besides the topology's per-vertex and per-face
///    arrays, memory is the impacts plus a few chunks of `CandidateBuffer::kStreamChunk`
///    candidates per thread.

#include <crumple/core/types.hpp>
#include <crumple/detect/detector.hpp>
#include <crumple/detect/method.hpp>
#include <crumple/geometry/ccd.hpp>
#include <crumple/mesh/mesh.hpp>

#include <atomic>
#include <cstddef>
#include <filesystem>
#include <memory>
#include <ostream>
#include <span>
#include <vector>

namespace crumple {

/// A vertex and a face it is not a corner of that come within δ during the step.
struct VertexFaceImpact {
  Index vertex = -1;
  Index face = -1;
  /// Conservative TOI in [0, 1]: no time before it brings the pair within δ.
  Scalar toi = 0;
  /// At x(toi): distance from the vertex to the face, the closest point's barycentric
  /// coordinates (face corners in order), and the unit vector from that point towards the
  /// vertex (when the distance is 0, the face's normal at toi, or zero for a degenerate face).
  Scalar distance = 0;
  Vec3 barycentric = Vec3::Zero();
  Vec3 normal = Vec3::Zero();
  /// How the narrow phase decided: `kHitTolerance` is a certified near-contact (docs/ccd.md);
  /// the other hit outcomes are conservative only (possibly false positives).
  geometry::CcdOutcome outcome = geometry::CcdOutcome::kHitTolerance;
};

/// Two edges sharing no vertex that come within δ during the step. `a` is the edge with the
/// smaller (first vertex, second vertex) pair; each edge's vertices are increasing.
struct EdgeEdgeImpact {
  Index edge0 = -1;  ///< mesh edge id of `a`
  Index edge1 = -1;  ///< mesh edge id of `b`
  Edge a{-1, -1};
  Edge b{-1, -1};
  Scalar toi = 0;  ///< as for `VertexFaceImpact::toi`
  /// At x(toi): the distance, the closest points (1 − s) a0 + s a1 and (1 − t) b0 + t b1, and
  /// the unit vector from the one on a towards the one on b (when the distance is 0, the
  /// normalised cross product of the edge directions, or zero when parallel).
  Scalar distance = 0;
  Scalar s = 0;
  Scalar t = 0;
  Vec3 normal = Vec3::Zero();
  geometry::CcdOutcome outcome = geometry::CcdOutcome::kHitTolerance;
};

/// The impacts of one step, sorted: VF by (vertex, face), EE by (a, b).
struct ImpactSet {
  std::vector<VertexFaceImpact> vf;
  std::vector<EdgeEdgeImpact> ee;
  void clear() {
    vf.clear();
    ee.clear();
  }
  std::size_t size() const { return vf.size() + ee.size(); }
  bool empty() const { return size() == 0; }
};

/// The impact of a narrow-phase hit `r` (`geometry::ccd`) of a vertex (start[0] → end[0])
/// against a triangle (start[1..3] → end[1..3], corners in order): its time, outcome and
/// geometry at x(toi), as every continuous query records them; `vertex` and `face` left at -1.
VertexFaceImpact vertex_face_impact(const geometry::CcdPoints& start, const geometry::CcdPoints& end,
                                    const geometry::CcdResult& r);
/// Same for edges a (points 0, 1) and b (points 2, 3); ids and endpoints left at -1.
EdgeEdgeImpact edge_edge_impact(const geometry::CcdPoints& start, const geometry::CcdPoints& end,
                                const geometry::CcdResult& r);

/// The largest step t ∈ [0, 1] this set allows: the earliest conservative TOI, or 1 when there
/// is no impact. Nothing comes within δ before it (it is 0 when a pair is within δ at t = 0).
Scalar collision_free_step(const ImpactSet& impacts);

/// Writes the stable text format, one impact a line, in the set's (sorted) order:
///   `vf <vertex> <face> <toi> <w0> <w1> <w2> <nx> <ny> <nz>`
///   `ee <a0> <a1> <b0> <b1> <toi> <s> <t> <nx> <ny> <nz>`
/// Numbers with 17 significant digits (round-trip exact).
void write_impacts(std::ostream& out, const ImpactSet& impacts);
/// Same, atomically to a file (core/atomic_file.hpp); throws `ParseError` naming the file.
void write_impacts_file(const std::filesystem::path& path, const ImpactSet& impacts);

struct ContinuousOptions {
  /// δ ≥ 0 in scene units (finite): report pairs that come within this distance.
  Scalar min_separation = 0;
  /// The broad phase: `kdop` (swept whatever its `sweep` key says), `hash` or `sap`, with
  /// their parameters (docs/exact-detectors.md); `max_contacts` and `overflow` are ignored.
  MethodSpec method{Method::Kdop};
  /// Worker threads: 0 = all hardware threads, 1 = serial. The impacts do not depend on it.
  int threads = 0;
  /// Narrow-phase options; its `min_separation` is replaced by the one above.
  geometry::CcdOptions narrow{};
};

/// A continuous query over one topology, kept across steps (the broad phase's structures are
/// refitted, not rebuilt, from one step to the next).
class ContinuousQuery {
 public:
  /// Throws `InputError` for a method other than kdop, hash or sap, a bad method parameter, a
  /// negative or non-finite δ, or bad narrow-phase options.
  ContinuousQuery(std::shared_ptr<const Topology> topology, ContinuousOptions options);
  ~ContinuousQuery();
  ContinuousQuery(const ContinuousQuery&) = delete;
  ContinuousQuery& operator=(const ContinuousQuery&) = delete;

  const Topology& topology() const { return *topology_; }
  const ContinuousOptions& options() const { return options_; }

  /// The impacts of the step from `previous` to `current` (#V positions each) into `out`
  /// (replacing its contents). Throws `InputError` when a size differs from the vertex count
  /// or a coordinate is not finite (naming the vertex and the frame); `out` is then empty.
  void query(PositionsView previous, PositionsView current, ImpactSet& out);

  /// The impacts of `query(previous, current)` whose pair has at least one vertex flagged in
  /// `moved` (#V flags: the vertex of a VF pair or a corner of its face, an end of either edge
  /// of an EE pair), bit for bit the same, in the same order; `moved` all zero gives none.
  /// Such a pair is owned by a face pair of which one face touches a flagged vertex, so only
  /// those faces query a tree of every face (kept across calls, refitted where vertices moved,
  /// pruned by the slab test: docs/simulation.md, "The CCD fail-safe") and the orphans with a
  /// flagged vertex are tested: the cost follows the flagged region, not the mesh. The broad
  /// phase's own structure is neither refitted nor rebuilt (the next `query` refits it). Same
  /// errors as `query`, and `InputError` when `moved` does not have #V entries.
  void query_moved(PositionsView previous, PositionsView current, std::span<const char> moved, ImpactSet& out);

  /// A bound on the pairs a query needs: those whose vertices move together are left out.
  /// A pair's *relative displacement* is the largest |uᵢ − uⱼ| over a vertex i of one side (the
  /// vertex of a VF pair, an edge of an EE pair) and j of the other, uᵢ = x¹ᵢ − x⁰ᵢ.
  struct MotionBound {
    std::span<const char> exempt;  ///< #V flags: a pair with a flagged vertex is never left out
    Scalar reach = 0;              ///< finite, >= 0
  };
  /// `query_moved`'s impacts less (some of) those of pairs with no vertex flagged in
  /// `bound.exempt` and a relative displacement at most `bound.reach`: every impact of a pair
  /// with an exempt vertex or a relative displacement above `bound.reach (1 + 1e-12)` is kept,
  /// bit for bit and in order, and nothing else is added. Faces whose corners move together are
  /// passed over as whole subtrees of the tree of every face (each node holds the box of its
  /// corners' displacements), so a fast region that moves as one costs only where it meets
  /// what moves otherwise. The caller proves the left-out pairs harmless (the fail-safe: docs/
  /// simulation.md, "The first query restricted by the start's proximity"). Same errors as
  /// `query_moved`, and `InputError` when `exempt` does not have #V entries or the reach is
  /// negative or not finite.
  void query_moved(PositionsView previous, PositionsView current, std::span<const char> moved,
                   const MotionBound& bound, ImpactSet& out);
  /// `query`'s impacts less (some of) those of pairs that `bound` covers, as `query_moved` with
  /// every vertex flagged; but the sweep of the broad phase: its face pairs whose corners all
  /// move within the reach of each other are dropped before their sub-pairs are tested, and so
  /// are the orphan sub-pairs around a vertex whose closed one-ring (every orphan's four vertices
  /// lie in the one-ring of a vertex both faces share) moves within the reach.
  void query(PositionsView previous, PositionsView current, const MotionBound& bound, ImpactSet& out);

  /// Turns `impacts`, the query (`query`, or this call) of a motion that differs from the one
  /// from `previous` to `current` only at vertices flagged in `moved`, into the query of this
  /// one, bit for bit and in order: the impacts of pairs with a flagged vertex are replaced by
  /// `query_moved`'s, the others are kept (the narrow phase's answer for a pair depends only on
  /// its four vertices' motions). Same errors as `query_moved` (`impacts` is then empty).
  void update_moved(PositionsView previous, PositionsView current, std::span<const char> moved, ImpactSet& impacts);

  /// Counters and timings of the last `query`: `candidates` (face pairs from the broad
  /// phase), `vf_box_rejected` / `ee_box_rejected` (sub-pairs the slab test drops: the narrow
  /// phase's difference-hull filter, run first from per-time boxes), `face_pairs_apart`
  /// (candidates whose faces' boxes are apart, all their sub-pairs dropped at once),
  /// `vf_tests` / `ee_tests` (narrow-phase calls), `orphan_vf` / `orphan_ee`,
  /// `isolated_vertices`, `vf_impacts` / `ee_impacts`, `conservative_hits` (impacts decided by
  /// budget, precision or range only), `narrow_boxes`, `narrow_advance_steps`,
  /// `narrow_<outcome>` (tests per `CcdOutcome`, e.g. `narrow_separated-hull`); `update_ms`
  /// (broad-phase refit, sort or hash), `stream_ms` (wall time of the candidate stream:
  /// traversal and the narrow phase of its candidates, interleaved on the threads),
  /// `narrow_cpu_ms` (thread time spent in the narrow phase inside the stream), `orphan_ms`,
  /// `sort_ms`, `total_ms`; and the broad phase's own counters (`query_moved`: `moved_faces`,
  /// the faces touching a flagged vertex, `face_tree_built` and `face_slabs_refitted`); with a
  /// `MotionBound`, `face_pairs_together` (the sweep's candidates dropped as moving together)
  /// and `orphans_calm` (the sweep's orphans dropped around a calm vertex).
  const DetectorStats& stats() const { return stats_; }

  /// The collision-free step of the step from `previous` to `current`: exactly
  /// `crumple::collision_free_step` of `query`'s impacts, for every method and thread count,
  /// but faster: each narrow-phase test searches only before the running minimum of the TOIs
  /// found so far (`CcdOptions::max_time`; a hit before it is found exactly as without it),
  /// and no impact is stored. Same errors and stats as `query` (the impact counts are 0).
  Scalar collision_free_step(PositionsView previous, PositionsView current);

  /// The broad phase alone over this step (for benchmarks): its candidates are counted and
  /// dropped. Returns the count; sets `update_ms` and `stream_ms` in `stats()`.
  std::size_t count_candidates(PositionsView previous, PositionsView current);

  struct State;

 private:
  void run(PositionsView previous, PositionsView current, std::span<const char> moved, ImpactSet& out,
           std::atomic<Scalar>* earliest, const MotionBound* bound = nullptr);

  std::shared_ptr<const Topology> topology_;
  ContinuousOptions options_;
  DetectorStats stats_;
  std::unique_ptr<State> state_;
  ImpactSet fresh_;  ///< `update_moved`'s scratch
};

/// One-shot helpers: a `ContinuousQuery` for a single step.
ImpactSet continuous_impacts(std::shared_ptr<const Topology> topology, PositionsView previous,
                             PositionsView current, const ContinuousOptions& options = {});
Scalar collision_free_step(std::shared_ptr<const Topology> topology, PositionsView previous,
                           PositionsView current, const ContinuousOptions& options = {});

}  // namespace crumple
