#pragma once
/// \file
/// Conservative narrow-phase continuous collision detection (CCD) of one vertex–triangle (VF)
/// or edge–edge (EE) pair whose 4 points move linearly, x(t) = x⁰ + t (x¹ − x⁰), t ∈ [0, 1].
///
/// The question: do the two primitives come within a minimum separation δ ≥ 0 (Euclidean
/// distance ≤ δ; δ = 0 means touching) at some t ∈ [0, 1], and if so, from when?
///
/// Method: inclusion-based bisection of the parameter box (t, u, v) ∈ [0, 1]³ after
/// Wang, Ferguson, Panozzo, Zorin, Schneider, "A Large-Scale Benchmark and an Inclusion-Based
/// Algorithm for Continuous Collision Detection", ACM TOG 40(5), 2021 (Tight-Inclusion), with
/// our own forward rounding-error bound (docs/ccd.md derives it), preceded by certified
/// filters (the hull of the difference points; for δ = 0, the Bernstein signs of the
/// coplanarity cubic with Shewchuk's orient3d error bound per mixed determinant; fixed
/// separating directions) and by certified conservative advancement along the closest-point
/// direction, which proves most pairs apart or lands on the contact, and otherwise leaves the
/// bisection only [t_k, 1].
///
/// Guarantees (for finite inputs of magnitude ≤ 2^1000, IEEE binary64 round-to-nearest, no
/// fused multiply-add contraction — the library is built with -ffp-contract=off):
///  - No false negatives: `hit == false` only when no t ∈ [0, 1] brings the primitives within
///    Euclidean distance δ. Every rejection is certified by a rounding-error bound, never a
///    fixed epsilon.
///  - Conservative time: when `hit`, `toi` ≤ the first time the distance is ≤ δ.
///  - Tolerance (outcome `kHitTolerance` only): some time in [toi, toi + time_tolerance] brings
///    the primitives within Euclidean distance δ (1 + σ) + ε + 2‖err‖ (up to a relative 1e-15), where
///    err is `ccd_rounding_bound` (≈ 7e-15 × the largest coordinate) and ε the distance
///    tolerance (`distance_tolerance` × the query's extent). So a hit at `toi` is never far from
///    a real near-contact; its false positives stay within δ (1 + σ) + ε + 2‖err‖ (σ:
///    `separation_tolerance`).
///  - Other hit outcomes (`kHitBudget`, `kHitPrecision`, `kHitOutOfRange`) are conservative
///    only: the time is still a lower bound of the first contact, but no contact is claimed.
///  - Bounded work: at most `max_advance_steps` advancement steps and `max_boxes` boxes, then
///    a hit is reported at the earliest time not yet ruled out, which is never before the
///    advancement's certified time: a pair apart by more than δ (and the rounding band) at
///    t = 0 never gets a TOI of 0.
///  - Scale: a query whose largest coordinate lies outside [2^-300, 2^300] (and within the
///    range, 2^1000) is computed on its points and δ (rounded up) scaled by a power of two into
///    [1, 2) when that loses no bit of a coordinate, so it is decided as at unit scale; err is
///    then that of the scaled query, scaled back.

#include <crumple/core/types.hpp>

#include <array>
#include <cstdint>
#include <span>
#include <string_view>

namespace crumple::geometry {

/// Which pair a CCD query is: the vertex then the triangle's 3 vertices, or edge a's two
/// endpoints then edge b's.
enum class CcdPair : std::uint8_t { kVertexFace, kEdgeEdge };

/// How a query was decided; the first five are "no hit".
enum class CcdOutcome : std::uint8_t {
  kSeparatedHull,         ///< the difference points' hull misses the δ box on some axis
  kSeparatedCoplanarity,  ///< δ = 0 and the 4 points are never coplanar (Bernstein signs)
  kSeparatedDirection,    ///< the difference points project beyond δ along a normal direction
  kSeparatedBisection,    ///< every box of the bisection was rejected
  kSeparatedAdvancement,  ///< conservative advancement along directions reached t = 1
  kHitTolerance,          ///< a box corner at t ≤ t0 + time_tolerance is within δ(1+σ) + ε + 2‖err‖
  kHitPrecision,          ///< a box could not be split further (dyadic depth limit)
  kHitBudget,             ///< `max_boxes` reached; reported at the earliest live time
  kHitOutOfRange,         ///< non-finite input or magnitude > 2^1000; reported at t = 0
};

/// Number of `CcdOutcome` values (for per-outcome counters).
inline constexpr int kCcdOutcomeCount = 9;

/// Name of an outcome, e.g. "separated-hull".
std::string_view to_string(CcdOutcome outcome);

struct CcdOptions {
  /// δ ≥ 0, in the input's units.
  Scalar min_separation = 0;
  /// Width in t below which a box that meets the distance tolerance is reported. Clamped to
  /// [2^-40, 1].
  Scalar time_tolerance = 1e-6;
  /// ε relative to the query's extent (the largest |coordinate| of the difference points);
  /// never below 4 × the rounding bound.
  Scalar distance_tolerance = 1e-6;
  /// σ ≥ 0: with δ > 0, a hit may be reported once the primitives are within δ (1 + σ) + ε
  /// (the δ-sphere is met tangentially, so demanding δ + ε alone costs many boxes).
  Scalar separation_tolerance = 0.01;
  /// Most boxes examined before a conservative hit (≥ 1).
  std::int64_t max_boxes = 10000;
  /// Most conservative-advancement steps before bisection takes over (≥ 0; 0: bisection only).
  std::int64_t max_advance_steps = 4096;
  /// Only contacts before this time are wanted (for a running minimum of TOIs). A hit with
  /// `toi` < max_time is reported exactly as with max_time = 1; any other query may stop as
  /// soon as no contact before max_time remains possible and report no hit (outcome
  /// `kSeparatedAdvancement` or `kSeparatedBisection`). In [0, 1].
  Scalar max_time = 1;
};

struct CcdResult {
  bool hit = false;
  /// Conservative time of impact in [0, 1] when `hit`; 1 otherwise.
  Scalar toi = 1;
  CcdOutcome outcome = CcdOutcome::kSeparatedHull;
  /// Boxes examined by the bisection (0 when a filter or the advancement decided).
  std::int64_t boxes = 0;
  /// Conservative-advancement steps taken.
  std::int64_t advance_steps = 0;
};

/// The 4 points of a query at t = 0 (`start`) and t = 1 (`end`), in the order of `CcdPair`.
using CcdPoints = std::array<Vec3, 4>;

/// Vertex start[0]→end[0] against triangle (start[1..3])→(end[1..3]).
CcdResult vertex_face_ccd(const CcdPoints& start, const CcdPoints& end, const CcdOptions& options = {});
/// Edge (start[0], start[1])→(end[0], end[1]) against edge (start[2], start[3])→(end[2], end[3]).
CcdResult edge_edge_ccd(const CcdPoints& start, const CcdPoints& end, const CcdOptions& options = {});
/// Either, by `pair`.
CcdResult ccd(CcdPair pair, const CcdPoints& start, const CcdPoints& end, const CcdOptions& options = {});

/// One query's 4 points at t = 0 and t = 1, in the order of `CcdPair`.
struct CcdQuery {
  CcdPoints start, end;
};

/// `out[i]` = `ccd(pair, queries[i].start, queries[i].end, options)` for every query (all of
/// type `pair`), field for field (hit, the TOI's bits, outcome, boxes, steps), at a higher
/// throughput: with AVX2 the filters run four queries at a time in vector lanes and the
/// conservative advancement of four queries in lockstep (docs/ccd.md, "Many queries at once").
/// `out` must have one element per query.
void ccd(CcdPair pair, std::span<const CcdQuery> queries, const CcdOptions& options, std::span<CcdResult> out);

/// Per time τ ∈ {0, 1}, the coordinate-wise min `lo[τ]` and max `hi[τ]` of a feature's points
/// (a vertex, an edge's endpoints, a triangle's corners) at t = τ.
struct CcdSlabs {
  std::array<Vec3, 2> lo, hi;
};

/// A bound for `ccd_slabs_apart` valid for every query whose coordinates are all at most
/// `magnitude` in absolute value: at least the err + δ (rounded up) that `ccd`'s difference-hull
/// filter uses on every axis (the same expression, monotone in the magnitude). +∞ when
/// `magnitude` exceeds 2^1000 or is not finite: such queries are out of range, never rejected.
Scalar ccd_hull_bound(Scalar magnitude, Scalar delta);

/// `ccd`'s difference-hull filter (docs/ccd.md, step 2) from the two features' slabs: true when
/// on some axis, at t = 0 and at t = 1 alike, every rounded difference a − b of a point of `a`
/// and a point of `b` exceeds `bound` (or every one is below −bound). Rounding is monotone, so
/// fl(lo_a − hi_b) is the smallest of the rounded differences fl(a_i − b_j) that `ccd` tests:
/// with `bound` = `ccd_hull_bound` of a magnitude ≥ every coordinate, a true answer means that
/// `ccd` on the pair returns `kSeparatedHull` (certified: no contact), whatever the order of the
/// features and points. Branch-free (its outcome is unpredictable in a candidate loop), and
/// always inlined (a candidate loop calls it for every sub-pair).
__attribute__((always_inline)) inline bool ccd_slabs_apart(const CcdSlabs& a, const CcdSlabs& b, Scalar bound) {
  int apart = 0;
  for (int k = 0; k < 3; ++k) {
    apart |= int(a.lo[0][k] - b.hi[0][k] > bound) & int(a.lo[1][k] - b.hi[1][k] > bound);
    apart |= int(b.lo[0][k] - a.hi[0][k] > bound) & int(b.lo[1][k] - a.hi[1][k] > bound);
  }
  return apart != 0;
}

/// err, per axis: a certified bound on the absolute rounding error of every difference value
/// F(t, u, v) the bisection evaluates for these points (64 u · max|coordinate| + 2^-1000,
/// u = 2^-53; docs/ccd.md derives the 30 u the evaluation needs).
Vec3 ccd_rounding_bound(const CcdPoints& start, const CcdPoints& end);

}  // namespace crumple::geometry
