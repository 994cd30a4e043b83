#pragma once
/// \file
/// The exact kernels four at a time, bit-identical to the scalar ones: segment-segment
/// (`segment_segment`) and point-triangle (`point_triangle`) distances, with what a contact
/// needs of them.
///
/// The narrow phase of the exact detectors calls these kernels hundreds of thousands of times a
/// frame, and the scalar kernels spend most of each call on branches whose outcome depends on
/// the configuration. A batch
/// evaluates every branch of the same method for four pairs in vector lanes and selects each
/// lane's outcome. Every lane performs the scalar kernel's operations, in its order, with no
/// contraction into fused multiply-adds, so the results are the scalar kernel's bits
/// (tests/geometry/segment_batch_test.cpp and point_triangle_batch_test.cpp compare them on
/// random, degenerate and adversarial inputs). The lanes are one AVX2 register, so the batches
/// run only on a CPU with AVX2 (`has_avx2()`, asked at run time); elsewhere callers use the
/// scalar kernels (on two 128-bit halves the segment batch is slower than the scalar kernel).
///
/// The triangle-triangle intersection test (`triangles_intersect`) is exact, so its batch
/// (`triangles_intersect_x4`) gives the same answers by deciding only what its filters certify
/// and handing the rest to the scalar test (tests/geometry/triangle_batch_test.cpp).

#include <crumple/geometry/distance.hpp>

#include <array>
#include <cstddef>

namespace crumple::geometry {

/// Up to four pairs of a kernel's inputs, `Points` points each (segment-segment: p0 p1 against
/// q0 q1; point-triangle: p against a b c; triangle-triangle: a0 a1 a2 against b0 b1 b2),
/// structure of arrays: `coords[k][i]` is coordinate k % 3 of point k / 3 of pair i. Unused
/// lanes may hold anything finite (their results are not read).
template <std::size_t Points>
struct PointBatch {
  static constexpr std::size_t kLanes = 4;
  alignas(32) std::array<std::array<Scalar, kLanes>, 3 * Points> coords{};
  /// Stores pair i.
  template <class... P>
  void set(std::size_t i, const P&... x) {
    static_assert(sizeof...(P) == Points);
    const Vec3* points[Points] = {&x...};
    for (std::size_t k = 0; k < 3 * Points; ++k) coords[k][i] = (*points[k / 3])[static_cast<Eigen::Index>(k % 3)];
  }
  /// Point `point` of pair i, as `set` stored it.
  Vec3 get(std::size_t i, std::size_t point) const {
    return Vec3(coords[3 * point][i], coords[3 * point + 1][i], coords[3 * point + 2][i]);
  }
};
using FourPointBatch = PointBatch<4>;
/// Segment pairs (p0, p1, q0, q1).
using SegmentBatch = FourPointBatch;
/// Point-triangle pairs (p, a, b, c).
using PointTriangleBatch = FourPointBatch;
/// Triangle pairs (a0, a1, a2, b0, b1, b2).
using TrianglePairBatch = PointBatch<6>;

/// The squared distances and parameters of the batch's four pairs: exactly what
/// `segment_segment` returns for each (same bits). With them, the same bits as these
/// computations on its result r: `distance` = sqrt(r.sqr_distance), `gap_norm` =
/// (r.closest1 - r.closest0).norm() and `normal` = (r.closest1 - r.closest0) / gap_norm, whose
/// coordinate i for pair k is normal[i][k] (a contact's distance and normal; where gap_norm is
/// 0 the normal is not finite).
struct SegmentBatchResult {
  alignas(32) std::array<Scalar, SegmentBatch::kLanes> sqr_distance{}, s{}, t{}, distance{}, gap_norm{};
  alignas(32) std::array<std::array<Scalar, SegmentBatch::kLanes>, 3> normal{};
};

/// For each pair of a `PointTriangleBatch`, the bits that `point_triangle` gives, r, and what a
/// contact computes from them: `sqr_distance` = r.sqr_distance, `barycentric[i]` =
/// r.barycentric[i], `distance` = sqrt(r.sqr_distance), `away_norm` = (p - r.closest).norm()
/// and `normal[i]` = (p - r.closest)[i] / away_norm (not finite where away_norm is 0).
/// Coordinate i of pair k is x[i][k].
struct PointTriangleBatchResult {
  alignas(32) std::array<Scalar, PointTriangleBatch::kLanes> sqr_distance{}, distance{}, away_norm{};
  alignas(32) std::array<std::array<Scalar, PointTriangleBatch::kLanes>, 3> barycentric{}, normal{};
};

/// Whether this CPU has AVX2, which the `_x4` functions need.
bool has_avx2();

/// The four pairs of `batch` as `segment_segment` would give them, at once. Only where
/// `has_avx2()`.
SegmentBatchResult segment_segment_x4(const SegmentBatch& batch);

/// The four pairs of `batch` as `point_triangle` would give them, at once. Only where
/// `has_avx2()`.
PointTriangleBatchResult point_triangle_x4(const PointTriangleBatch& batch);

/// The first `count` pairs of `batch` that `triangles_intersect` says intersect, as a mask (bit
/// i for pair i). The answers are exact, so they are that function's: the lanes evaluate the
/// same orientation determinants (each triangle's corners against the other's plane, then Guigue
/// and Devillers' two for triangles that straddle each other's planes) with the same
/// floating-point filter, and a lane whose filter cannot decide a sign that its answer needs
/// (near-degenerate, touching or coplanar triangles) is answered by `triangles_intersect`
/// itself. Where `deferred` is given, it receives the mask of those lanes. Only where
/// `has_avx2()`.
unsigned triangles_intersect_x4(const TrianglePairBatch& batch, std::size_t count, unsigned* deferred = nullptr);

}  // namespace crumple::geometry
