#pragma once
/// \file
/// Independent higher-precision oracles for the distance kernels (tests only).
///
///  - point-segment: golden-section search over t in long double (64-bit mantissa) on the
///    convex function |a + t (b - a) - p|^2, plus both endpoints;
///  - segment-segment and point-triangle: exact enumeration of the candidate minimisers in
///    binary128 (__float128, 113-bit mantissa): the minimum of a convex quadratic over the
///    square / the triangle is either its interior critical point or a minimum on one side of
///    the domain, and a side minimum is a point-segment distance (closed form). Every
///    candidate evaluated is a point of the domain, so the oracle never under-estimates by
///    more than its rounding; with 113 bits the differences and pairwise products of double
///    inputs are exact, and the interior critical points are computed with cross products
///    (errors relative to |u x v|, not to |u x v|^2), so near-parallel segments and slivers
///    down to sin(angle) ~ 1e-16 are still solved to ~1e-18 relative.
/// None of this shares code or algorithm with the kernels (no region classification, no
/// clamped-root walk).

#include <crumple/core/types.hpp>

#include <algorithm>
#include <limits>

namespace crumple::geometry::test {

#if defined(__SIZEOF_FLOAT128__)
__extension__ typedef __float128 Quad;  // x86-64 (GCC, Clang): software binary128
#else
static_assert(std::numeric_limits<long double>::digits >= 113,
              "the distance oracles need a binary128 type (__float128 or a 128-bit long double)");
typedef long double Quad;  // AArch64 Linux: long double is binary128
#endif

struct Q3 {
  Quad x, y, z;
};
inline Q3 to_q(const Vec3& v) { return {Quad(v.x()), Quad(v.y()), Quad(v.z())}; }
inline Q3 operator-(const Q3& a, const Q3& b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
inline Q3 operator+(const Q3& a, const Q3& b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
inline Q3 operator*(Quad s, const Q3& a) { return {s * a.x, s * a.y, s * a.z}; }
inline Quad dot(const Q3& a, const Q3& b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
inline Q3 cross(const Q3& a, const Q3& b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}

/// Squared distance from p to segment [a,b] (closed-form clamp, binary128).
inline Quad quad_point_segment(const Q3& p, const Q3& a, const Q3& b) {
  const Q3 u = b - a;
  const Q3 ap = p - a;
  const Quad uu = dot(u, u);
  Quad t = 0;
  if (uu > 0) t = std::clamp(dot(ap, u) / uu, Quad(0), Quad(1));
  const Q3 diff = ap - t * u;
  return dot(diff, diff);
}

/// Oracle squared distance between segments [p0,p1] and [q0,q1].
inline long double oracle_segment_segment(const Vec3& p0d, const Vec3& p1d, const Vec3& q0d,
                                          const Vec3& q1d) {
  const Q3 p0 = to_q(p0d), p1 = to_q(p1d), q0 = to_q(q0d), q1 = to_q(q1d);
  Quad best = quad_point_segment(p0, q0, q1);
  best = std::min(best, quad_point_segment(p1, q0, q1));
  best = std::min(best, quad_point_segment(q0, p0, p1));
  best = std::min(best, quad_point_segment(q1, p0, p1));
  // Interior critical point of the two lines, by the cross-product formulas
  //   s = ((q0 - p0) x v).n / |n|^2,  t = ((q0 - p0) x u).n / |n|^2,  n = u x v,
  // whose errors stay relative to |n| (Cramer on the Gram matrix, with det = ac - b^2,
  // would lose 1/sin^2 of the angle even in binary128).
  const Q3 u = p1 - p0, v = q1 - q0, w = q0 - p0;
  const Q3 n = cross(u, v);
  const Quad nn = dot(n, n);
  if (nn > 0) {
    const Quad s = dot(cross(w, v), n) / nn, t = dot(cross(w, u), n) / nn;
    if (s >= 0 && s <= 1 && t >= 0 && t <= 1) {
      const Q3 diff = (p0 + s * u) - (q0 + t * v);
      best = std::min(best, dot(diff, diff));
    }
  }
  return static_cast<long double>(best);
}

/// Oracle squared distance from p to triangle (a,b,c), degenerate triangles included.
inline long double oracle_point_triangle(const Vec3& pd, const Vec3& ad, const Vec3& bd,
                                         const Vec3& cd) {
  const Q3 p = to_q(pd), a = to_q(ad), b = to_q(bd), c = to_q(cd);
  Quad best = quad_point_segment(p, a, b);
  best = std::min(best, quad_point_segment(p, b, c));
  best = std::min(best, quad_point_segment(p, c, a));
  // Foot of p on the plane, in barycentrics by the cross-product (area) formulas
  //   s = ((p - a) x e1).n / |n|^2,  t = (e0 x (p - a)).n / |n|^2,  n = e0 x e1.
  const Q3 e0 = b - a, e1 = c - a, ap = p - a;
  const Q3 n = cross(e0, e1);
  const Quad nn = dot(n, n);
  if (nn > 0) {
    const Quad s = dot(cross(ap, e1), n) / nn, t = dot(cross(e0, ap), n) / nn;
    if (s >= 0 && t >= 0 && s + t <= 1) {
      const Q3 diff = (a + s * e0 + t * e1) - p;
      best = std::min(best, dot(diff, diff));
    }
  }
  return static_cast<long double>(best);
}

/// Oracle squared distance from p to segment [a,b]: golden-section search in long double.
inline long double oracle_point_segment(const Vec3& pd, const Vec3& ad, const Vec3& bd) {
  using LD = long double;
  const LD px = pd.x(), py = pd.y(), pz = pd.z();
  const LD ax = ad.x(), ay = ad.y(), az = ad.z();
  const LD ux = LD(bd.x()) - ax, uy = LD(bd.y()) - ay, uz = LD(bd.z()) - az;
  const auto f = [&](LD t) {
    const LD dx = ax - px + t * ux, dy = ay - py + t * uy, dz = az - pz + t * uz;
    return dx * dx + dy * dy + dz * dz;
  };
  const LD g = 0.61803398874989484820458683436563811772L;
  LD lo = 0, hi = 1;
  LD x1 = hi - g * (hi - lo), x2 = lo + g * (hi - lo);
  LD f1 = f(x1), f2 = f(x2);
  for (int it = 0; it < 100; ++it) {
    if (f1 <= f2) {
      hi = x2, x2 = x1, f2 = f1;
      x1 = hi - g * (hi - lo);
      f1 = f(x1);
    } else {
      lo = x1, x1 = x2, f1 = f2;
      x2 = lo + g * (hi - lo);
      f2 = f(x2);
    }
  }
  return std::min({f1, f2, f(0), f(1), f((lo + hi) / 2)});
}

}  // namespace crumple::geometry::test
