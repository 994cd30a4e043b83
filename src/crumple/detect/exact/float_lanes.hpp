#pragma once
/// \file
/// Internal to the exact detector: box tests in four float lanes (GCC's vector extensions) on
/// coordinates rounded to float, with pads that cover the rounding, so that a test that
/// rejects in float also rejects in exact arithmetic.

#include <crumple/core/types.hpp>

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>

namespace crumple::exact {

/// Four float lanes (GCC's vector extensions: SSE on x86-64 without asking for more).
using F4 = float __attribute__((vector_size(16)));
using I4 = std::int32_t __attribute__((vector_size(16)));

__attribute__((always_inline)) inline F4 load4(const std::array<float, 4>& a) {
  F4 v;
  std::memcpy(&v, a.data(), sizeof v);
  return v;
}
/// Bit l set: lane l of v is true (all ones), for the lanes 0-2.
__attribute__((always_inline)) inline unsigned lanes3(const I4& v) {
#if defined(__SSE__)
  return static_cast<unsigned>(__builtin_ia32_movmskps(std::bit_cast<F4>(v))) & 7u;
#else
  return (v[0] != 0 ? 1u : 0u) | (v[1] != 0 ? 2u : 0u) | (v[2] != 0 ? 4u : 0u);
#endif
}
/// 1 when every lane of v is true (all ones), else 0.
__attribute__((always_inline)) inline unsigned all_lanes(const I4& v) {
#if defined(__SSE__)
  return (static_cast<unsigned>(__builtin_ia32_movmskps(std::bit_cast<F4>(v))) + 1) >> 4;
#else
  return (v[0] != 0) & (v[1] != 0) & (v[2] != 0) & (v[3] != 0) ? 1u : 0u;
#endif
}
__attribute__((always_inline)) inline F4 min4(const F4& a, const F4& b) { return a < b ? a : b; }
__attribute__((always_inline)) inline F4 max4(const F4& a, const F4& b) { return a > b ? a : b; }
template <int L>
__attribute__((always_inline)) inline F4 lane(const F4& v) {
  return __builtin_shufflevector(v, v, L, L, L, L);
}

/// A face's corners rounded to float (`coarse_coordinate`), axis by axis: coordinate d of
/// corner k in lane k of axes[d], and of corner 0 again in lane 3; from the corners' (x, y, z,
/// 0) lanes.
using CoarseAxes = std::array<F4, 3>;
__attribute__((always_inline)) inline CoarseAxes coarse_axes(const F4& c0, const F4& c1, const F4& c2) {
  const F4 xy = __builtin_shufflevector(c0, c1, 0, 4, 1, 5);  // x0 x1 y0 y1
  const F4 zz = __builtin_shufflevector(c0, c1, 2, 6, 2, 6);  // z0 z1 z0 z1
  return {__builtin_shufflevector(xy, c2, 0, 1, 4, 0), __builtin_shufflevector(xy, c2, 2, 3, 5, 2),
          __builtin_shufflevector(zz, c2, 0, 1, 6, 0)};
}

/// The box rejections of a candidate face pair's sub-pairs, in float lanes on the faces'
/// corners rounded to float (`coarse_axes`). `vf`: bit k, corner k of the first face lies in
/// the second face's box padded by `pad` (bit 3 + k: corner k of the second in the first's
/// box); `ee`: bit 3i + j, the boxes of side i of the first face and side j of the second, each
/// padded by `half`, meet. The pads must cover the float rounding (`coarse_pad`), so that these
/// boxes hold the exact ones: a bit that is 0 is a sub-pair beyond the padded thickness. NaN: 0.
struct CoarseMasks {
  unsigned vf = 0, ee = 0;
};
__attribute__((always_inline)) inline CoarseMasks coarse_masks(const CoarseAxes& a, const CoarseAxes& b, float half,
                                                               float pad) {
  I4 in_a = {-1, -1, -1, -1}, in_b = in_a, meet0 = in_a, meet1 = in_a, meet2 = in_a;
  for (std::size_t d = 0; d < 3; ++d) {
    const F4 ca = a[d], cb = b[d];
    // Side k joins corners k and k + 1.
    const F4 na = __builtin_shufflevector(ca, ca, 1, 2, 0, 3), nb = __builtin_shufflevector(cb, cb, 1, 2, 0, 3);
    const F4 alo = min4(ca, na) - half, ahi = max4(ca, na) + half;
    const F4 blo = min4(cb, nb) - half, bhi = max4(cb, nb) + half;
    meet0 &= (lane<0>(alo) <= bhi) & (blo <= lane<0>(ahi));
    meet1 &= (lane<1>(alo) <= bhi) & (blo <= lane<1>(ahi));
    meet2 &= (lane<2>(alo) <= bhi) & (blo <= lane<2>(ahi));
    // The faces' boxes, in every lane (lane 3 repeats corner 0).
    const auto least = [](const F4& v) {
      const F4 m = min4(v, __builtin_shufflevector(v, v, 2, 3, 0, 1));
      return min4(m, __builtin_shufflevector(m, m, 1, 0, 3, 2));
    };
    const auto most = [](const F4& v) {
      const F4 m = max4(v, __builtin_shufflevector(v, v, 2, 3, 0, 1));
      return max4(m, __builtin_shufflevector(m, m, 1, 0, 3, 2));
    };
    in_a &= (least(cb) - pad <= ca) & (ca <= most(cb) + pad);
    in_b &= (least(ca) - pad <= cb) & (cb <= most(ca) + pad);
  }
  return {lanes3(in_a) | lanes3(in_b) << 3, lanes3(meet0) | lanes3(meet1) << 3 | lanes3(meet2) << 6};
}

/// A pad for `coarse_masks` that covers the float rounding of coordinates up to `extent` in
/// magnitude: the boxes it pads then hold the exact ones padded by `pad`. Corners are rounded
/// by at most u * extent (u = 2^-24), and a box's bound once more by u of itself: (pad + 3u
/// extent) / (1 - u) is enough, rounded up to a float; 8u is used.
inline float coarse_pad(Scalar pad, Scalar extent) {
  constexpr Scalar u = 0x1p-24;
  const Scalar wide = (pad + 8 * u * extent) * (1 + 8 * u) + 1e-37;
  if (!(wide <= std::numeric_limits<float>::max())) return std::numeric_limits<float>::infinity();
  auto f = static_cast<float>(wide);
  if (static_cast<Scalar>(f) < wide) f = std::nextafter(f, std::numeric_limits<float>::infinity());
  return f;
}

/// c rounded to float, for the float-lane box tests; beyond the float range clamped to it (the
/// tests are then off: `coarse_pad`'s caller gives infinite pads).
inline float coarse_coordinate(Scalar c) {
  constexpr Scalar kMax = std::numeric_limits<float>::max();
  return static_cast<float>(std::clamp(c, -kMax, kMax));
}

}  // namespace crumple::exact
