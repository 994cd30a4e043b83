#pragma once
/// \file
/// Four segment-segment distances at a time, bit-identical to `segment_segment`.
///
/// The narrow phase of the exact detectors calls the edge-edge kernel about 0.7 million times a
/// frame on cloth-ball, and the scalar kernel spends most of its ~40 ns a call on branches whose
/// outcome depends on the configuration. The batch evaluates every branch of the same method
/// for four pairs in vector lanes and selects each lane's outcome. Every lane performs the
/// scalar kernel's operations, in its order, with no contraction into fused multiply-adds, so
/// the results are the scalar kernel's bits (tests/geometry/segment_batch_test.cpp compares
/// them on random, degenerate and adversarial inputs). On a CPU with AVX2 the lanes are one
/// 256-bit register (chosen at run time); elsewhere the scalar kernel runs on each pair (two
/// 128-bit halves measured slower than the scalar kernel).

#include <crumple/geometry/distance.hpp>

#include <array>
#include <cstddef>

namespace crumple::geometry {

/// Up to four segment pairs (P = p0 p1 against Q = q0 q1), structure of arrays: `coords[k][i]`
/// is coordinate k % 3 of point k / 3 (p0, p1, q0, q1) of pair i. Unused lanes may hold
/// anything finite (their results are not read).
struct SegmentBatch {
  static constexpr std::size_t kLanes = 4;
  alignas(32) std::array<std::array<Scalar, kLanes>, 12> coords{};
  /// Stores pair i.
  void set(std::size_t i, const Vec3& p0, const Vec3& p1, const Vec3& q0, const Vec3& q1) {
    const Vec3* points[4] = {&p0, &p1, &q0, &q1};
    for (std::size_t k = 0; k < 12; ++k) coords[k][i] = (*points[k / 3])[static_cast<Eigen::Index>(k % 3)];
  }
};

/// The squared distances and parameters of the batch's four pairs: exactly what
/// `segment_segment` returns for each (same bits).
struct SegmentBatchResult {
  alignas(32) std::array<Scalar, SegmentBatch::kLanes> sqr_distance{}, s{}, t{};
};

/// The first `count` pairs of `batch` (at most four), as `segment_segment` would give them: with
/// AVX2, four at once; otherwise by `segment_segment` itself.
SegmentBatchResult segment_segment_x4(const SegmentBatch& batch, std::size_t count = SegmentBatch::kLanes);

/// Whether this CPU runs the AVX2 path.
bool has_avx2();
/// The AVX2 path itself, all four lanes (only where `has_avx2()`): for the tests.
SegmentBatchResult segment_segment_x4_avx2(const SegmentBatch& batch);

}  // namespace crumple::geometry
