#pragma once
/// \file
/// Inline definitions of the distance kernels declared in distance.hpp. Do not include
/// directly; include <crumple/geometry/distance.hpp>.
///
/// Numerical notes common to all kernels:
///  - Everything is computed in a frame local to one input point (differences first), so
///    that far from the origin only the rounding of the input differences (~eps * |coords|)
///    is lost, not the whole distance.
///  - The squared distance is |diff|^2 of the local difference vector at the returned
///    parameters, never the expanded quadratic form (which cancels catastrophically).
///  - No heap, no exceptions, no division by a quantity that can vanish: every division is
///    guarded by a sign test that keeps its quotient in [0, 1].
///  - Inputs must be finite; NaN coordinates give unspecified (but finite-time) results.

#include <crumple/geometry/distance.hpp>

#include <algorithm>

namespace crumple::geometry {

namespace detail {

/// Minimiser over [0,1] of the 1D convex quadratic whose derivative is num' = den*x - num:
/// 0 if num <= 0, 1 if num >= den, else num/den (in [0,1] since 0 < num < den).
inline Scalar clamped_ratio(Scalar num, Scalar den) {
  if (num <= 0) return 0;
  if (num >= den) return 1;
  return num / den;
}

/// Root in [0,1] of the increasing linear function h(x) with h(0) = h0, h(1) = h1 and
/// slope h1 - h0 = `slope` > 0, clamped to [0,1] (Eberly's GetClampedRoot): 0 if h0 >= 0,
/// 1 if h1 <= 0, else -h0/slope. A quotient outside [0,1] can only come from rounding
/// (h0 < 0 < h1 means |h0| < slope); it is then replaced by 0.5 as in GTE.
inline Scalar clamped_root(Scalar slope, Scalar h0, Scalar h1) {
  if (h0 >= 0) return 0;
  if (h1 <= 0) return 1;
  const Scalar r = -h0 / slope;
  return (r >= 0 && r <= 1) ? r : Scalar(0.5);
}

/// Feature of the triangle from the zero pattern of its barycentric coordinates. The
/// kernels set exact zeros for clamped coordinates, so this is exact, not a tolerance test.
inline TriangleRegion region_from_barycentric(const Vec3& w) {
  const bool z0 = w[0] == 0, z1 = w[1] == 0, z2 = w[2] == 0;
  if (z1 && z2) return TriangleRegion::VertexA;
  if (z0 && z2) return TriangleRegion::VertexB;
  if (z0 && z1) return TriangleRegion::VertexC;
  if (z2) return TriangleRegion::EdgeAB;
  if (z0) return TriangleRegion::EdgeBC;
  if (z1) return TriangleRegion::EdgeCA;
  return TriangleRegion::Face;
}

/// Fills barycentric, region and closest point; snaps the closest point to the corner
/// exactly for vertex regions (so a corner is reported bit-exactly), and recomputes the
/// squared distance from that corner.
inline void finish_point_triangle(PointTriangleResult& r, const Vec3& p, const Vec3& a,
                                  const Vec3& b, const Vec3& c) {
  r.region = region_from_barycentric(r.barycentric);
  const Vec3* corner = nullptr;
  switch (r.region) {
    case TriangleRegion::VertexA: corner = &a; break;
    case TriangleRegion::VertexB: corner = &b; break;
    case TriangleRegion::VertexC: corner = &c; break;
    default: break;
  }
  if (corner != nullptr) {
    r.closest = *corner;
    r.sqr_distance = (*corner - p).squaredNorm();
  }
}

/// Point to a degenerate triangle: the best of the three sides (ties: ab, then bc, then ca).
inline PointTriangleResult point_triangle_by_sides(const Vec3& p, const Vec3& a, const Vec3& b,
                                                   const Vec3& c) {
  const PointSegmentResult ab = point_segment(p, a, b);
  const PointSegmentResult bc = point_segment(p, b, c);
  const PointSegmentResult ca = point_segment(p, c, a);
  PointTriangleResult r;
  if (ab.sqr_distance <= bc.sqr_distance && ab.sqr_distance <= ca.sqr_distance) {
    r.sqr_distance = ab.sqr_distance;
    r.closest = ab.closest;
    r.barycentric = Vec3(1 - ab.t, ab.t, 0);
  } else if (bc.sqr_distance <= ca.sqr_distance) {
    r.sqr_distance = bc.sqr_distance;
    r.closest = bc.closest;
    r.barycentric = Vec3(0, 1 - bc.t, bc.t);
  } else {
    r.sqr_distance = ca.sqr_distance;
    r.closest = ca.closest;
    r.barycentric = Vec3(ca.t, 0, 1 - ca.t);
  }
  finish_point_triangle(r, p, a, b, c);
  return r;
}

/// A triangle is handled as degenerate when det = |e0 x e1|^2 <= kDegenerateSin2 *
/// |e0|^2 |e1|^2, i.e. sin^2 of its angle at a is below this (scale-free) threshold.
/// Below it the normal equations of the face solve lose about eps/sin^2 of relative
/// accuracy, while the error of replacing the face by its sides is at most the inradius
/// (<= ~sin * longest side). 1e-20 (angle ~1e-10 rad) keeps the side error at the
/// level of 1e-10 relative; tests/geometry/distance_test.cpp measures both sides of it.
inline constexpr Scalar kDegenerateSin2 = 1e-20;

}  // namespace detail

// ---------------------------------------------------------------------------------------------
// Point - segment: t = clamp(((p - a) . (b - a)) / |b - a|^2, 0, 1).
// ---------------------------------------------------------------------------------------------
inline PointSegmentResult point_segment(const Vec3& p, const Vec3& a, const Vec3& b) {
  const Vec3 u = b - a;
  const Vec3 ap = p - a;
  const Scalar t = detail::clamped_ratio(ap.dot(u), u.squaredNorm());
  PointSegmentResult r;
  r.t = t;
  if (t == 1) {
    r.closest = b;
    r.sqr_distance = (p - b).squaredNorm();
  } else {
    r.closest = a + t * u;
    r.sqr_distance = (ap - t * u).squaredNorm();
  }
  return r;
}

// ---------------------------------------------------------------------------------------------
// Segment - segment: Eberly's robust ("conjugate gradient") method, GTE DistSegmentSegment.h
// ComputeRobust, re-derived here.
//
// R(s,t) = |P(s) - Q(t)|^2 = a s^2 - 2 b st + c t^2 + 2 d s - 2 e t + f, with u = p1 - p0,
// v = q1 - q0, w = p0 - q0, a = u.u, b = u.v, c = v.v, d = u.w, e = v.w.
// Half-gradient: F(s,t) = a s - b t + d (= R_s/2), G(s,t) = -b s + c t - e (= R_t/2).
//
// Instead of solving the 2x2 system (division by ac - b^2 = |u x v|^2, which vanishes for
// parallel segments), the method follows the line F = 0 (the minimisers over s for each t):
//  1. s0, s1 = roots of F on the edges t = 0 and t = 1, clamped to [0,1].
//  2. If both clamp to 0 (or both to 1) the minimum lies on the edge s = 0 (s = 1): minimise
//     G along it.
//  3. Otherwise F = 0 crosses the unit square in a segment [E0, E1] (E on the square's
//     boundary). R restricted to it is a convex quadratic whose derivative along E0 -> E1 is
//     proportional to H = (t1 - t0) G (F vanishes there). If H(E0) >= 0 the minimum is at E0,
//     if H(E1) <= 0 at E1 (and when that end lies on s = 0 or s = 1 the true minimum may
//     slide along that edge: re-minimise G there); else it is the root of the linear H:
//     z = H0 / (H0 - H1).
// Divisions: by a > 0, c > 0, by b when the F = 0 line crosses an edge s = const (which
// implies b != 0 by sign), and by H0 - H1 > 0. Parallel segments (ac = b^2) need no special
// case: H is then constant along E0E1 and an end is chosen, deterministically E0 (the end on
// the lower edge t = 0 or on s = 0, in the order of the case analysis below).
// Zero-length segments (a == 0 and/or c == 0) reduce to point-segment / point-point.
// ---------------------------------------------------------------------------------------------
inline SegmentSegmentResult segment_segment(const Vec3& p0, const Vec3& p1, const Vec3& q0,
                                            const Vec3& q1) {
  using detail::clamped_root;
  const Vec3 u = p1 - p0;
  const Vec3 v = q1 - q0;
  const Vec3 w = p0 - q0;
  const Scalar a = u.dot(u), b = u.dot(v), c = v.dot(v), d = u.dot(w), e = v.dot(w);

  Scalar s = 0, t = 0;
  if (a > 0 && c > 0) {
    // F at the corners (s,t): f00 = F(0,0) etc.; G likewise.
    const Scalar f00 = d, f10 = d + a, f01 = d - b, f11 = f10 - b;
    const Scalar g00 = -e, g10 = -b - e, g01 = c - e, g11 = g10 + c;
    const Scalar s_at_t0 = clamped_root(a, f00, f10);
    const Scalar s_at_t1 = clamped_root(a, f01, f11);
    const int k0 = s_at_t0 <= 0 ? -1 : (s_at_t0 >= 1 ? 1 : 0);
    const int k1 = s_at_t1 <= 0 ? -1 : (s_at_t1 >= 1 ? 1 : 0);
    if (k0 == -1 && k1 == -1) {
      s = 0;
      t = clamped_root(c, g00, g01);
    } else if (k0 == 1 && k1 == 1) {
      s = 1;
      t = clamped_root(c, g10, g11);
    } else {
      // Ends of the F = 0 line inside the square; edge codes: 0 -> s=0, 1 -> s=1,
      // 2 -> t=0, 3 -> t=1. t on s = 0 is f00/b, on s = 1 it is f10/b (b != 0 here).
      int edge0, edge1;
      Scalar s_e0, t_e0, s_e1, t_e1;
      const auto t_on_s0 = [&] { return std::clamp(f00 / b, Scalar(0), Scalar(1)); };
      const auto t_on_s1 = [&] { return std::clamp(f10 / b, Scalar(0), Scalar(1)); };
      if (k0 == -1) {
        edge0 = 0, s_e0 = 0, t_e0 = t_on_s0();
        if (k1 == 0) {
          edge1 = 3, s_e1 = s_at_t1, t_e1 = 1;
        } else {
          edge1 = 1, s_e1 = 1, t_e1 = t_on_s1();
        }
      } else if (k0 == 0) {
        edge0 = 2, s_e0 = s_at_t0, t_e0 = 0;
        if (k1 == -1) {
          edge1 = 0, s_e1 = 0, t_e1 = t_on_s0();
        } else if (k1 == 0) {
          edge1 = 3, s_e1 = s_at_t1, t_e1 = 1;
        } else {
          edge1 = 1, s_e1 = 1, t_e1 = t_on_s1();
        }
      } else {
        edge0 = 1, s_e0 = 1, t_e0 = t_on_s1();
        if (k1 == 0) {
          edge1 = 3, s_e1 = s_at_t1, t_e1 = 1;
        } else {
          edge1 = 0, s_e1 = 0, t_e1 = t_on_s0();
        }
      }
      const Scalar dt = t_e1 - t_e0;
      const Scalar h0 = dt * (-b * s_e0 + c * t_e0 - e);
      const auto end_point = [&](int edge, Scalar se, Scalar te) {
        if (edge == 0) {
          s = 0;
          t = clamped_root(c, g00, g01);
        } else if (edge == 1) {
          s = 1;
          t = clamped_root(c, g10, g11);
        } else {
          s = se;
          t = te;
        }
      };
      if (h0 >= 0) {
        end_point(edge0, s_e0, t_e0);
      } else {
        const Scalar h1 = dt * (-b * s_e1 + c * t_e1 - e);
        if (h1 <= 0) {
          end_point(edge1, s_e1, t_e1);
        } else {
          const Scalar z = std::clamp(h0 / (h0 - h1), Scalar(0), Scalar(1));
          const Scalar omz = 1 - z;
          s = std::clamp(omz * s_e0 + z * s_e1, Scalar(0), Scalar(1));
          t = std::clamp(omz * t_e0 + z * t_e1, Scalar(0), Scalar(1));
        }
      }
    }
  } else if (a > 0) {
    // Q is a point: minimise over s only.
    s = clamped_root(a, d, d + a);
  } else if (c > 0) {
    // P is a point: minimise over t only.
    t = clamped_root(c, -e, c - e);
  }

  SegmentSegmentResult r;
  r.s = s;
  r.t = t;
  r.closest0 = s == 1 ? p1 : Vec3(p0 + s * u);
  r.closest1 = t == 1 ? q1 : Vec3(q0 + t * v);
  r.sqr_distance = (w + s * u - t * v).squaredNorm();
  return r;
}

// ---------------------------------------------------------------------------------------------
// Point - triangle: Eberly's region classification (GTE DistPointTriangle.h; Schneider &
// Eberly 2003 §10.3.2), re-derived, computed in the frame of corner a.
//
// T(s,t) = a + s e0 + t e1, e0 = b - a, e1 = c - a, d = a - p,
// Q(s,t) = |T(s,t) - p|^2 = a00 s^2 + 2 a01 st + a11 t^2 + 2 b0 s + 2 b1 t + |d|^2,
// a00 = e0.e0, a01 = e0.e1, a11 = e1.e1, b0 = e0.d, b1 = e1.d.
// Unconstrained minimiser (s~, t~)/det with s~ = a01 b1 - a11 b0, t~ = a01 b0 - a00 b1,
// det = a00 a11 - a01^2 = |e0 x e1|^2. Its position relative to the triangle
// (s >= 0, t >= 0, s + t <= 1, tested on the unnormalised values) picks one of 7 regions:
//
//          t
//      \ 2 |
//        \ |
//          c      region 0: inside            -> (s~, t~)/det
//          |\     regions 1, 3, 5: beyond one side -> clamp the 1D minimum on that side
//        3 | \ 1  regions 2, 4, 6: beyond a corner -> the sign of the gradient along the two
//          |0 \                               incident sides picks the side holding the minimum
//      ----a---b---- s
//        4 |  5 \ 6
//
// Side parameters use the direct projections (p - a).e0/|e0|^2, (p - a).e1/|e1|^2 and
// (p - b).(c - b)/|c - b|^2 rather than the expanded quadratic form.
//
// Degenerate triangles: det <= kDegenerateSin2 * a00 * a11 (collinear or coincident corners,
// slivers with an angle below ~1e-10 rad at a) -> best of the three sides (point_segment).
// ---------------------------------------------------------------------------------------------
inline PointTriangleResult point_triangle(const Vec3& p, const Vec3& a, const Vec3& b,
                                          const Vec3& c) {
  using detail::clamped_ratio;
  const Vec3 e0 = b - a;
  const Vec3 e1 = c - a;
  const Vec3 d = a - p;
  const Scalar a00 = e0.dot(e0), a01 = e0.dot(e1), a11 = e1.dot(e1);
  const Scalar b0 = e0.dot(d), b1 = e1.dot(d);
  const Scalar det = a00 * a11 - a01 * a01;
  if (!(det > detail::kDegenerateSin2 * a00 * a11)) {
    return detail::point_triangle_by_sides(p, a, b, c);
  }

  // The three possible answers on a side; each sets (w, diff) where diff = closest - p.
  PointTriangleResult r;
  Vec3 diff;
  const auto on_ab = [&] {  // t = 0
    const Scalar s = clamped_ratio(-b0, a00);
    r.barycentric = Vec3(1 - s, s, 0);
    diff = d + s * e0;
    r.closest = a + s * e0;
  };
  const auto on_ca = [&] {  // s = 0
    const Scalar t = clamped_ratio(-b1, a11);
    r.barycentric = Vec3(1 - t, 0, t);
    diff = d + t * e1;
    r.closest = a + t * e1;
  };
  const auto on_bc = [&] {  // s + t = 1, parameter x from b toward c
    const Vec3 e2 = c - b;
    const Vec3 pb = b - p;
    const Scalar x = clamped_ratio(-pb.dot(e2), e2.squaredNorm());
    r.barycentric = Vec3(0, 1 - x, x);
    diff = pb + x * e2;
    r.closest = b + x * e2;
  };

  const Scalar s_num = a01 * b1 - a11 * b0;
  const Scalar t_num = a01 * b0 - a00 * b1;
  if (s_num + t_num <= det) {
    if (s_num < 0) {
      if (t_num < 0) {
        // Region 4 (beyond a): dQ/ds at a is b0; if negative the minimum is on ab.
        if (b0 < 0) {
          on_ab();
        } else {
          on_ca();
        }
      } else {
        on_ca();  // region 3
      }
    } else if (t_num < 0) {
      on_ab();  // region 5
    } else {
      // Region 0: interior.
      const Scalar inv = 1 / det;
      const Scalar s = s_num * inv, t = t_num * inv;
      r.barycentric = Vec3(std::max(Scalar(0), 1 - s - t), s, t);
      diff = d + s * e0 + t * e1;
      r.closest = a + s * e0 + t * e1;
    }
  } else {
    if (s_num < 0) {
      // Region 2 (beyond c): at c, the derivative along c -> b is (p - c).(c - b)-like:
      // minimum on bc iff moving from c toward b decreases Q, i.e. (c - p).(c - b) > 0.
      const Vec3 cp = c - p;
      if (cp.dot(c - b) > 0) {
        on_bc();
      } else {
        on_ca();
      }
    } else if (t_num < 0) {
      // Region 6 (beyond b): minimum on bc iff moving from b toward c decreases Q.
      const Vec3 bp = b - p;
      if (bp.dot(b - c) > 0) {
        on_bc();
      } else {
        on_ab();
      }
    } else {
      on_bc();  // region 1
    }
  }
  r.sqr_distance = diff.squaredNorm();
  detail::finish_point_triangle(r, p, a, b, c);
  return r;
}

}  // namespace crumple::geometry
