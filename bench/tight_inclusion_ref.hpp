#pragma once
// An independent re-implementation of Tight-Inclusion's narrow-phase CCD (Wang, Ferguson,
// Schneider, Jiang, Attene, Panozzo, "A Large-Scale Benchmark and an Inclusion-Based Algorithm
// for Continuous Collision Detection", ACM TOG 40(5), 2021), breadth-first variant, written from
// the description in ALGORITHMS-2 §1.1 and checked against the behaviour of the public code
// (Continuous-Collision-Detection/Tight-Inclusion, src/tight_inclusion/). For benchmarks and
// tests only: the baseline that issue 42's throughput goal names. Not part of the library.
//
// The question it answers (the authors' contract): `hit == false` only when the primitives
// never come closer than `min_separation` during [0, t_max]; a hit may be a false positive
// within tolerance + min_separation + err per axis; `toi` is a lower bound of the first
// contact time.
//
// Differences from the authors' binary, none of which changes a decision:
//  - Interval ends are doubles, not (numerator, 2^-power) pairs: splits are exact in binary64
//    up to 52 levels (TI's uint64 numerators stop at 63), and (x1 − x0)·k / 2^n, TI's
//    evaluation, rounds to the same double as (x1 − x0)·(k / 2^n).
//  - The 4 points' positions at a box's two times are evaluated once per axis instead of once
//    per corner (the same expressions, so the same values).
//  - The queue's storage is reused across queries (TI allocates a priority queue per query).
// The last two make this port cheaper than the original, never dearer.
#include <crumple/core/types.hpp>

#include <array>
#include <cstdint>

namespace crumple::ti_ref {

/// Tight-Inclusion's parameters, with the values ipc-toolkit's `TightInclusionCCD` passes by
/// default (`DEFAULT_TOLERANCE` 1e-6, `DEFAULT_MAX_ITERATIONS` 1e7, err computed per query,
/// t_max = 1; `no_zero_toi` is only used by ipc-toolkit's rerun at toi < 1e-6 and is not
/// implemented here).
struct Settings {
  /// δ_tol: the target codomain width (scene units).
  Scalar tolerance = 1e-6;
  /// Most boxes examined before a conservative hit at the first live box of the current level
  /// (≤ 0: no cap).
  std::int64_t max_iterations = 10'000'000;
  /// Only [0, t_max] is searched.
  Scalar t_max = 1;
};

struct Result {
  bool hit = false;
  /// Lower bound of the first contact time when `hit`; +∞ otherwise (TI's convention).
  Scalar toi = 0;
  /// The codomain width actually reached: `tolerance`, or more when `max_iterations` stopped it.
  Scalar output_tolerance = 0;
  /// Boxes examined (TI's `refine` counter).
  std::int64_t boxes = 0;
};

using Points = std::array<Vec3, 4>;

/// err per axis: c · max(1, max |coordinate k| over the 8 points)³, with c = 30, 28, 34, 32 × 2^-52
/// for VF, EE, VF with δ > 0, EE with δ > 0 (TI's `get_numerical_error`; the original max(·, 1),
/// not the min(·, 1) of TI's later refactor, ALGORITHMS-2 §1.1).
std::array<Scalar, 3> numerical_error(const Points& start, const Points& end, bool vertex_face,
                                      bool minimum_separation);

/// Vertex start[0]→end[0] against triangle start[1..3]→end[1..3], within `min_separation` ≥ 0.
Result vertex_face_ccd(const Points& start, const Points& end, Scalar min_separation, const Settings& settings = {});
/// Edge (start[0], start[1]) against edge (start[2], start[3]), within `min_separation` ≥ 0.
Result edge_edge_ccd(const Points& start, const Points& end, Scalar min_separation, const Settings& settings = {});

}  // namespace crumple::ti_ref
