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
///    inputs are exact and near-singular systems (near-parallel segments, slivers down to
///    sin^2 ~ 1e-24) are still solved to many digits.
/// None of this shares code or algorithm with the kernels (no region classification, no
/// clamped-root walk).

#include <crumple/core/types.hpp>

#include <algorithm>

namespace crumple::geometry::test {

__extension__ typedef __float128 Quad;

struct Q3 {
  Quad x, y, z;
};
inline Q3 to_q(const Vec3& v) { return {Quad(v.x()), Quad(v.y()), Quad(v.z())}; }
inline Q3 operator-(const Q3& a, const Q3& b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
inline Q3 operator+(const Q3& a, const Q3& b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
inline Q3 operator*(Quad s, const Q3& a) { return {s * a.x, s * a.y, s * a.z}; }
inline Quad dot(const Q3& a, const Q3& b) { return a.x * b.x + a.y * b.y + a.z * b.z; }

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
  const Q3 u = p1 - p0, v = q1 - q0, w = p0 - q0;
  const Quad a = dot(u, u), b = dot(u, v), c = dot(v, v), d = dot(u, w), e = dot(v, w);
  const Quad det = a * c - b * b;
  if (det > 0) {
    const Quad s = (b * e - c * d) / det, t = (a * e - b * d) / det;
    if (s >= 0 && s <= 1 && t >= 0 && t <= 1) {
      const Q3 diff = w + s * u - t * v;
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
  const Q3 e0 = b - a, e1 = c - a, d = a - p;
  const Quad a00 = dot(e0, e0), a01 = dot(e0, e1), a11 = dot(e1, e1);
  const Quad b0 = dot(e0, d), b1 = dot(e1, d);
  const Quad det = a00 * a11 - a01 * a01;
  if (det > 0) {
    const Quad s = (a01 * b1 - a11 * b0) / det, t = (a01 * b0 - a00 * b1) / det;
    if (s >= 0 && t >= 0 && s + t <= 1) {
      const Q3 diff = d + s * e0 + t * e1;
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
