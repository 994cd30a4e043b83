#pragma once
/// \file
/// Internal: the face-level slab test of the mesh-level continuous query (continuous.cpp),
/// exposed for its tests.

#include <crumple/core/types.hpp>

#include <array>

namespace crumple::detail {

/// A face's box at t = 0 and at t = 1, each bound rounded outwards to float, indexed
/// [3 τ + axis]: the lows, then the highs. (16-byte aligned: the kernels' two-float loads at
/// lo[4] and hi[4] are then 8-byte aligned.)
struct alignas(16) FaceBoxes {
  std::array<float, 6> lo, hi;
};

/// Whether on some axis, at t = 0 and at t = 1 alike, one face's low minus the other's high,
/// converted to double and subtracted there (one rounding), exceeds `bound`:
/// `geometry::ccd_slabs_apart`'s test on the float boxes. `avx2` (only where
/// `geometry::detail::ccd_has_avx2()`) picks the kernel of three four-wide differences, else
/// the one of six two-wide (SSE2) differences; both give the same answer.
bool face_boxes_apart(const FaceBoxes& a, const FaceBoxes& b, Scalar bound, bool avx2);

}  // namespace crumple::detail
