#pragma once
/// \file
/// Cheap lower bounds of a distance, for rejecting pairs before the exact kernels: a point is
/// at least as far from a triangle as from its plane, and two segments at least as far apart
/// as their lines. The exact detectors' narrow phase runs these tests on about two million
/// sub-pairs a frame on cloth-ball; `beyond_x4` runs four at a time in AVX2 lanes, with the
/// scalar test's operations in its order (no fused multiply-adds: AVX2 only), so its verdicts
/// are the scalar ones bit for bit (tests/geometry/separation_test.cpp).

#include <crumple/core/types.hpp>

#include <array>
#include <cmath>
#include <cstddef>
#include <limits>

#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#define CRUMPLE_SEPARATION_LANES 1
#else
#define CRUMPLE_SEPARATION_LANES 0
#endif

namespace crumple::geometry {

/// The distance of a point to a plane, or between two lines, is |wn| / |n| for n the plane's
/// (the lines') normal and w a vector joining them; |wn| <= |w| |e1| |e2| <= `size`, the
/// product of the L1 norms of w and of the two vectors whose cross product n is.
struct Separation {
  Scalar wn;
  Vec3 n;
  Scalar size;
};

inline Scalar l1_norm(const Vec3& v) { return std::abs(v.x()) + std::abs(v.y()) + std::abs(v.z()); }

/// Point p against the plane of triangle (a, b, c): dist(p, triangle) >= dist(p, plane) =
/// |(p - a) . n| / |n|, n = (b - a) x (c - a).
inline Separation plane_separation(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) {
  const Vec3 e1 = b - a, e2 = c - a, w = p - a;
  const Vec3 n = e1.cross(e2);
  return {w.dot(n), n, l1_norm(w) * l1_norm(e1) * l1_norm(e2)};
}

/// Segments (p0, p1) and (q0, q1): dist(segments) >= dist(lines) = |w . (d0 x d1)| / |d0 x d1|,
/// w = q0 - p0.
inline Separation line_separation(const Vec3& p0, const Vec3& p1, const Vec3& q0, const Vec3& q1) {
  const Vec3 d0 = p1 - p0, d1 = q1 - q0, w = q0 - p0;
  const Vec3 n = d0.cross(d1);
  return {w.dot(n), n, l1_norm(w) * l1_norm(d0) * l1_norm(d1)};
}

/// |wn| / |n| > pad with a margin for the rounding of wn (1e-13 size, a hundred times its
/// bound), compared squared: no square root, the comparison's own rounding being far inside the
/// callers' margin of pad over the thickness. Degenerate n (parallel lines, a degenerate
/// triangle) or NaN: false. Branch-free: callers sift lists of which an unpredictable part is
/// rejected.
inline bool beyond(const Separation& s, Scalar pad) {
  const Scalar clear = std::abs(s.wn) - 1e-13 * s.size;
  return ((clear > 0) & (clear * clear > pad * pad * s.n.squaredNorm())) != 0;
}

/// A lower bound of |wn| / |n|, with `beyond`'s margin (degenerate n: -inf).
inline Scalar separation_bound(const Separation& s) {
  const Scalar nn = s.n.squaredNorm();
  return nn > 0 ? (std::abs(s.wn) - 1e-13 * s.size) / std::sqrt(nn) * (1 - 1e-12)
                : -std::numeric_limits<Scalar>::infinity();
}

/// The four points of a test: for a plane (kLine false) the point, then the triangle's corners
/// a, b, c; for a line (kLine true) the first segment's ends, then the second's.
using SeparationPoints = std::array<const Vec3*, 4>;

#if CRUMPLE_SEPARATION_LANES
namespace lanes {
// The vector types' ABI differs with and without AVX, which GCC warns about for functions that
// take them; those below are only inlined into functions compiled for AVX2.
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wpsabi"
using D4 = double __attribute__((vector_size(32)));
using M4 = long long __attribute__((vector_size(32)));
#define CRUMPLE_SEPARATION_INLINE inline __attribute__((always_inline, target("avx2")))

CRUMPLE_SEPARATION_INLINE D4 join(__m128d lo, __m128d hi) { return reinterpret_cast<D4>(_mm256_set_m128d(hi, lo)); }
/// Coordinates x, y, z of point k of each lane, one lane per test; each point is read as its
/// three coordinates and no further (the last vertex of a mesh ends its array).
CRUMPLE_SEPARATION_INLINE void transpose(const std::array<SeparationPoints, 4>& p, std::size_t k, D4 (&xyz)[3]) {
  const Scalar* q0 = p[0][k]->data();
  const Scalar* q1 = p[1][k]->data();
  const Scalar* q2 = p[2][k]->data();
  const Scalar* q3 = p[3][k]->data();
  const __m128d xy0 = _mm_loadu_pd(q0), xy1 = _mm_loadu_pd(q1), xy2 = _mm_loadu_pd(q2), xy3 = _mm_loadu_pd(q3);
  xyz[0] = join(_mm_unpacklo_pd(xy0, xy1), _mm_unpacklo_pd(xy2, xy3));
  xyz[1] = join(_mm_unpackhi_pd(xy0, xy1), _mm_unpackhi_pd(xy2, xy3));
  xyz[2] = join(_mm_loadh_pd(_mm_load_sd(q0 + 2), q1 + 2), _mm_loadh_pd(_mm_load_sd(q2 + 2), q3 + 2));
}
CRUMPLE_SEPARATION_INLINE D4 abs(D4 x) {
  return reinterpret_cast<D4>(reinterpret_cast<M4>(x) & (M4{} + 0x7fffffffffffffffLL));
}
CRUMPLE_SEPARATION_INLINE D4 l1_norm(const D4 (&v)[3]) { return abs(v[0]) + abs(v[1]) + abs(v[2]); }
CRUMPLE_SEPARATION_INLINE D4 dot(const D4 (&x)[3], const D4 (&y)[3]) { return x[0] * y[0] + x[1] * y[1] + x[2] * y[2]; }
#undef CRUMPLE_SEPARATION_INLINE
#pragma GCC diagnostic pop
}  // namespace lanes

/// Bit l set: the test of points[l] (`SeparationPoints`) is beyond pad, as
/// beyond(plane_separation or line_separation, pad) says, bit for bit. Compiled for AVX2: call
/// only where `has_avx2()` (kernel_batch.hpp) holds; inlined into callers compiled for AVX2.
template <bool kLine>
inline __attribute__((target("avx2"))) unsigned beyond_x4(const std::array<SeparationPoints, 4>& points, Scalar pad) {
  using lanes::D4;
  D4 c[4][3];
  for (std::size_t k = 0; k < 4; ++k) lanes::transpose(points, k, c[k]);
  // The scalar tests' vectors: w, and the two whose cross product is the normal.
  D4 w[3], d0[3], d1[3];
  for (std::size_t i = 0; i < 3; ++i) {
    if constexpr (kLine) {
      d0[i] = c[1][i] - c[0][i];
      d1[i] = c[3][i] - c[2][i];
      w[i] = c[2][i] - c[0][i];
    } else {
      d0[i] = c[2][i] - c[1][i];
      d1[i] = c[3][i] - c[1][i];
      w[i] = c[0][i] - c[1][i];
    }
  }
  // Eigen's cross product, coordinate by coordinate.
  const D4 n[3] = {d0[1] * d1[2] - d0[2] * d1[1], d0[2] * d1[0] - d0[0] * d1[2], d0[0] * d1[1] - d0[1] * d1[0]};
  const D4 size = lanes::l1_norm(w) * lanes::l1_norm(d0) * lanes::l1_norm(d1);
  const D4 clear = lanes::abs(lanes::dot(w, n)) - 1e-13 * size;
  const D4 pad2 = D4{} + pad * pad;
  const auto yes = (clear > D4{}) & (clear * clear > pad2 * lanes::dot(n, n));
  return static_cast<unsigned>(_mm256_movemask_pd(reinterpret_cast<__m256d>(yes)));
}
#endif

}  // namespace crumple::geometry
