#pragma once
/// \file
/// Exact orientation predicates (adaptive: a floating-point filter, then exact arithmetic).
///
/// Method: J. R. Shewchuk, "Adaptive Precision Floating-Point Arithmetic and Fast Robust
/// Geometric Predicates", Discrete Comput. Geom. 18 (1997). The determinant is first evaluated
/// in plain double precision; Shewchuk's a-priori error bound (his `o3derrboundA`,
/// `ccwerrboundA`) decides whether its sign is certain. Only when it is not (near-degenerate
/// or exactly degenerate input) the determinant is recomputed exactly with floating-point
/// expansions (predicates.cpp). The implementation here is our own; only the bounds are his.
///
/// Assumptions and failure modes:
///  - IEEE-754 binary64 with round-to-nearest-even and no extended precision (x86-64 SSE2,
///    AArch64). The exact stage uses `std::fma` for its products when the target has a fast
///    FMA (FP_FAST_FMA) and Dekker's splitting otherwise. Contraction of the filter's
///    `a*b + c` into FMAs (GCC does it only when FMA instructions are enabled, e.g. -mfma or
///    AArch64) removes roundings; we expect the error bound to stay valid but have not
///    re-derived it for that case.
///  - Inputs must be finite, with non-zero coordinates of magnitude within ~[1e-60, 1e60]:
///    outside, the products of three coordinates and their rounding errors may underflow
///    or overflow and the returned sign may be wrong. NaN gives an unspecified sign.
///  - Cost of the exact stage: none when two points coincide (tested first); short
///    expansions when the coordinate differences are exact in double (nearby points,
///    Sterbenz); expansions about ten times as costly otherwise.

#include <crumple/core/types.hpp>

#include <array>
#include <cmath>

namespace crumple::geometry {

namespace detail {
/// Exact sign of det[b - a; c - a; d - a] by expansion arithmetic, no filter.
int orient3d_exact(const Vec3& a, const Vec3& b, const Vec3& c, const Vec3& d);
/// Exact sign of (a - c) x (b - c) by expansion arithmetic, no filter.
int orient2d_exact(Scalar ax, Scalar ay, Scalar bx, Scalar by, Scalar cx, Scalar cy);

/// Unit roundoff of binary64, 2^-53 (Shewchuk's epsilon).
inline constexpr Scalar kRoundoff = 0x1p-53;
/// Shewchuk's bound: |fl(det) - det| <= kOrient3dBound * permanent for the evaluation below.
inline constexpr Scalar kOrient3dBound = (7.0 + 56.0 * kRoundoff) * kRoundoff;
/// Same for the 2D determinant.
inline constexpr Scalar kOrient2dBound = (3.0 + 16.0 * kRoundoff) * kRoundoff;
/// The sign of det[b - a; c - a; d - a] from its floating-point value `det` and `permanent`
/// (the bound's argument), or from the exact expansion when the filter cannot decide.
inline int orient3d_sign(Scalar det, Scalar permanent, const Vec3& a, const Vec3& b, const Vec3& c, const Vec3& d) {
  const Scalar bound = kOrient3dBound * permanent;
  if (det > bound) return 1;
  if (-det > bound) return -1;
  return orient3d_exact(a, b, c, d);
}
}  // namespace detail

/// Exact sign of det[b - a; c - a; d - a] = ((b - a) x (c - a)) . (d - a).
///
/// +1 when d lies strictly on the side of the plane through a, b, c toward which the normal
/// (b - a) x (c - a) points (i.e. a, b, c counter-clockwise seen from d), -1 on the other side,
/// 0 when the four points are coplanar (including when a, b, c are collinear or coincide).
/// Note: this is the opposite sign convention of Shewchuk's `orient3d`.
/// Cost: ~20 flops when the filter decides (nearly always on non-degenerate input).
inline int orient3d(const Vec3& a, const Vec3& b, const Vec3& c, const Vec3& d) {
  const Scalar ux = b.x() - a.x(), uy = b.y() - a.y(), uz = b.z() - a.z();
  const Scalar vx = c.x() - a.x(), vy = c.y() - a.y(), vz = c.z() - a.z();
  const Scalar wx = d.x() - a.x(), wy = d.y() - a.y(), wz = d.z() - a.z();
  // det = ux (vy wz - vz wy) + uy (vz wx - vx wz) + uz (vx wy - vy wx)
  const Scalar vywz = vy * wz, vzwy = vz * wy;
  const Scalar vzwx = vz * wx, vxwz = vx * wz;
  const Scalar vxwy = vx * wy, vywx = vy * wx;
  const Scalar det = ux * (vywz - vzwy) + uy * (vzwx - vxwz) + uz * (vxwy - vywx);
  const Scalar permanent = std::abs(ux) * (std::abs(vywz) + std::abs(vzwy)) +
                           std::abs(uy) * (std::abs(vzwx) + std::abs(vxwz)) +
                           std::abs(uz) * (std::abs(vxwy) + std::abs(vywx));
  return detail::orient3d_sign(det, permanent, a, b, c, d);
}

/// {orient3d(a, b, c, d0), orient3d(a, b, c, d1), orient3d(a, b, c, d2)}: the sides of three
/// points of the plane through a, b, c. The filter shares the plane's minors: it evaluates
/// det = (d - a) . ((b - a) x (c - a)) as w_x (u_y v_z - u_z v_y) + ... (w = d - a, u = b - a,
/// v = c - a), the form `orient3d` evaluates with the rows in another order (each term a rounded
/// difference times a difference of products of rounded differences), so the same bound
/// holds; undecided signs come from the same exact expansion.
inline std::array<int, 3> orient3d_sides(const Vec3& a, const Vec3& b, const Vec3& c, const Vec3& d0,
                                         const Vec3& d1, const Vec3& d2) {
  const Scalar ux = b.x() - a.x(), uy = b.y() - a.y(), uz = b.z() - a.z();
  const Scalar vx = c.x() - a.x(), vy = c.y() - a.y(), vz = c.z() - a.z();
  const Scalar uyvz = uy * vz, uzvy = uz * vy;
  const Scalar uzvx = uz * vx, uxvz = ux * vz;
  const Scalar uxvy = ux * vy, uyvx = uy * vx;
  const Scalar mx = uyvz - uzvy, my = uzvx - uxvz, mz = uxvy - uyvx;
  const Scalar px = std::abs(uyvz) + std::abs(uzvy), py = std::abs(uzvx) + std::abs(uxvz),
               pz = std::abs(uxvy) + std::abs(uyvx);
  const auto side = [&](const Vec3& d) {
    const Scalar wx = d.x() - a.x(), wy = d.y() - a.y(), wz = d.z() - a.z();
    return detail::orient3d_sign(wx * mx + wy * my + wz * mz, std::abs(wx) * px + std::abs(wy) * py + std::abs(wz) * pz,
                                 a, b, c, d);
  };
  return {side(d0), side(d1), side(d2)};
}

/// Exact sign of the 2D determinant (a - c) x (b - c) = (ax-cx)(by-cy) - (ay-cy)(bx-cx):
/// +1 when a, b, c turn counter-clockwise, -1 clockwise, 0 collinear (or coincident).
inline int orient2d(Scalar ax, Scalar ay, Scalar bx, Scalar by, Scalar cx, Scalar cy) {
  const Scalar left = (ax - cx) * (by - cy);
  const Scalar right = (ay - cy) * (bx - cx);
  const Scalar det = left - right;
  const Scalar bound = detail::kOrient2dBound * (std::abs(left) + std::abs(right));
  if (det > bound) return 1;
  if (-det > bound) return -1;
  return detail::orient2d_exact(ax, ay, bx, by, cx, cy);
}

/// orient2d of the projections of a, b, c onto the coordinate plane that drops axis
/// `drop` (0, 1 or 2): the kept coordinates are ((drop+1)%3, (drop+2)%3), so the result
/// equals the sign of the `drop` component of (b - a) x (c - a). Exact.
inline int orient2d_projected(const Vec3& a, const Vec3& b, const Vec3& c, int drop) {
  const int i = (drop + 1) % 3, j = (drop + 2) % 3;
  return orient2d(a[i], a[j], b[i], b[j], c[i], c[j]);
}

}  // namespace crumple::geometry
