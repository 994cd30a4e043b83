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
///  - No heap, no exceptions. Every divisor is positive by a preceding test (or non-zero by a
///    sign argument, noted at the division), and quotients that must lie in [0, 1] are
///    clamped there, so rounding can never produce a parameter outside the domain.
///  - Inputs must be finite; NaN coordinates give unspecified (but finite-time) results.

#include <crumple/geometry/distance.hpp>

#include <algorithm>
#include <limits>

namespace crumple::geometry {

namespace detail {

/// Minimiser over [0,1] of a 1D convex quadratic with derivative proportional to den*x - num
/// (den >= 0): 0 if num <= 0, 1 if num >= den, else num/den (then 0 < num < den).
inline Scalar clamped_ratio(Scalar num, Scalar den) {
  if (num <= 0) return 0;
  if (num >= den) return 1;
  return num / den;
}

/// Root in [0,1] of the increasing linear function h(x) with h(0) = h0, h(1) = h1 and
/// slope h1 - h0 = `slope` > 0, clamped to [0,1] (Eberly's GetClampedRoot): 0 if h0 >= 0,
/// 1 if h1 <= 0, else -h0/slope (> 0). When h0 and h1 were rounded separately the quotient
/// can exceed 1 by a few ulps; it is clamped to 1 (GTE substitutes 0.5, half a segment away
/// from the true root, which is then near 1).
inline Scalar clamped_root(Scalar slope, Scalar h0, Scalar h1) {
  if (h0 >= 0) return 0;
  if (h1 <= 0) return 1;
  const Scalar r = -h0 / slope;
  return r < 1 ? r : Scalar(1);
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

/// A triangle is handled as degenerate (replaced by its sides) when its squared height over
/// its longest side is at most kFlatRatio times that side's squared length, i.e. the
/// height is below 8 eps times the longest side: collinear or coincident corners up to
/// rounding. Scale-free.
inline constexpr Scalar kFlatRatio = 64 * 0x1p-53 * 0x1p-53;

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
// case: H is then constant along E0E1 and an end is chosen deterministically (E0 if H >= 0,
// else E1; E0 is the end on s = 0 or t = 0 in the case analysis below), then re-minimised
// along its edge, so overlapping parallel segments always get the same one of their
// infinitely many closest pairs.
// Zero-length segments (a == 0 and/or c == 0) reduce to point-segment / point-point.
//
// Deviation from GTE (accuracy only, same decisions in exact arithmetic): H is evaluated from
// vectors orthogonalised against u (see below), which keeps the distance error O(eps * L) for
// near-parallel segments, where GTE's scalar evaluation loses up to ~1e-8 * L
// (tests/geometry/distance_test.cpp holds the near-parallel cases).
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
      // Along F = 0 the closest point of line P to Q(t) is taken, so the difference vector is
      // w_perp - t v_perp (the parts of w and v orthogonal to u) and G = t |v_perp|^2 -
      // v_perp . w_perp. Evaluating G this way instead of as -b s + c t - e avoids the
      // cancellation (absolute error eps |v|^2 against a slope |v_perp|^2 = c sin^2(angle))
      // that costs GTE's version up to ~sqrt(eps) * L of distance for near-parallel
      // segments that (nearly) cross.
      const Vec3 v_perp = v - (b / a) * u;
      const Vec3 w_perp = w - (d / a) * u;
      const Scalar g_slope = v_perp.squaredNorm(), g_offset = v_perp.dot(w_perp);
      const Scalar dt = t_e1 - t_e0;
      const Scalar h0 = dt * (g_slope * t_e0 - g_offset);
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
        const Scalar h1 = dt * (g_slope * t_e1 - g_offset);
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
// Eberly 2003 §10.3.2), with the projection computed by Gram-Schmidt (QR) instead of the
// normal equations.
//
// The seven regions of the plane around the triangle are the sign patterns of the barycentric
// coordinates (w0, w1, w2) of the orthogonal projection ("foot") of p onto the plane:
//
//            \ 2 /            region 0: all w >= 0      -> the foot itself (face)
//              c               regions 1, 3, 5: one w < 0 -> the side opposite that corner
//           3 / \ 1           regions 2, 4, 6: two w < 0 -> the best of the two sides opposite
//            / 0 \                                         them (Eberly decides between them
//      ---- a --- b ----                                    by a gradient sign; evaluating both
//        4  |  5  |  6                                      is as cheap and cannot pick wrong)
//
// A side answer is point_segment on that side, clamped (a corner when clamped).
//
// Frame. Eberly forms the normal equations [a00 a01; a01 a11] (s, t) = -(b0, b1), whose
// determinant |e0 x e1|^2 cancels catastrophically for thin triangles: the foot is then off by
// ~eps*L/sin^2(angle) and the region signs become noise near sin^2 ~ eps (errors of order L).
// Here the frame is local to the first corner of the *longest* side (P0 -> P1, third corner
// P2; the longest side keeps |x_r| <= 1 below), and is orthogonalised explicitly:
//   e = P1 - P0, r = P2 - P0, q = p - P0,
//   x_r = r.e/|e|^2, x_q = q.e/|e|^2      (coordinates along the base side)
//   r_perp = r - x_r e, q_perp = q - x_q e   (parts orthogonal to it; |r_perp| = height H)
//   y = q_perp.r_perp / H^2               (coordinate of the foot along r_perp)
//   foot = P0 + x_q e + y r_perp, so w2 = y, w1 = x_q - y x_r, w0 = 1 - w1 - w2,
//   and in region 0 the squared distance is |q_perp - y r_perp|^2.
// Every quantity has an absolute error of a few eps*L in the metric of the plane, so the
// distance is within O(eps*L) of the exact one even for slivers (only the barycentrics of a
// sliver are ill-conditioned, as they must be).
//
// Degenerate triangles: H^2 <= kFlatRatio * |e|^2 (collinear or coincident corners, within
// rounding) -> best of the three sides (point_segment); the error of that replacement is at
// most the inradius < H/2 <= 4 eps * |e|.
// ---------------------------------------------------------------------------------------------
inline PointTriangleResult point_triangle(const Vec3& p, const Vec3& a, const Vec3& b,
                                          const Vec3& c) {
  const Vec3 ab = b - a, bc = c - b, ca = a - c;
  const Scalar lab = ab.squaredNorm(), lbc = bc.squaredNorm(), lca = ca.squaredNorm();
  // Rotate the corners so that the base P0 -> P1 is the longest side; `rot` says how.
  int rot;
  const Vec3 *p0, *p1, *p2, *e;
  Scalar l2;
  if (lab >= lbc && lab >= lca) {
    rot = 0, p0 = &a, p1 = &b, p2 = &c, e = &ab, l2 = lab;
  } else if (lbc >= lca) {
    rot = 1, p0 = &b, p1 = &c, p2 = &a, e = &bc, l2 = lbc;
  } else {
    rot = 2, p0 = &c, p1 = &a, p2 = &b, e = &ca, l2 = lca;
  }
  // Barycentrics given for (P0, P1, P2) -> for (a, b, c).
  const auto unrotate = [rot](Scalar w0, Scalar w1, Scalar w2) {
    return rot == 0 ? Vec3(w0, w1, w2) : (rot == 1 ? Vec3(w2, w0, w1) : Vec3(w1, w2, w0));
  };

  PointTriangleResult r;
  if (!(l2 > 0)) {  // all corners coincide (or non-finite input)
    r.barycentric = Vec3(1, 0, 0);
    r.closest = a;
    r.sqr_distance = (a - p).squaredNorm();
    r.region = TriangleRegion::VertexA;
    return r;
  }
  const Vec3 rv = *p2 - *p0;
  const Vec3 q = p - *p0;
  const Scalar inv_l2 = 1 / l2;
  const Scalar x_r = rv.dot(*e) * inv_l2;
  const Vec3 r_perp = rv - x_r * *e;
  const Scalar h2 = r_perp.squaredNorm();
  if (!(h2 > detail::kFlatRatio * l2)) return detail::point_triangle_by_sides(p, a, b, c);

  const Scalar x_q = q.dot(*e) * inv_l2;
  const Vec3 q_perp = q - x_q * *e;
  const Scalar y = q_perp.dot(r_perp) / h2;
  const Scalar w2 = y, w1 = x_q - y * x_r, w0 = 1 - w1 - w2;

  if (w0 >= 0 && w1 >= 0 && w2 >= 0) {  // region 0
    const Vec3 offset = x_q * *e + y * r_perp;
    r.closest = *p0 + offset;
    r.sqr_distance = (q - offset).squaredNorm();
    r.barycentric = unrotate(w0, w1, w2);
  } else {
    // The closest point lies on a side whose line separates the foot from the triangle
    // (for a corner answer, at least one of its two sides does), i.e. opposite a negative w.
    r.sqr_distance = std::numeric_limits<Scalar>::infinity();
    const auto side = [&](const Vec3& from, const Vec3& to, int i_from, int i_to) {
      const PointSegmentResult s = point_segment(p, from, to);
      if (s.sqr_distance < r.sqr_distance) {
        r.sqr_distance = s.sqr_distance;
        r.closest = s.closest;
        Scalar w[3] = {0, 0, 0};
        w[i_from] = 1 - s.t;
        w[i_to] = s.t;
        r.barycentric = unrotate(w[0], w[1], w[2]);
      }
    };
    if (w2 < 0) side(*p0, *p1, 0, 1);
    if (w0 < 0) side(*p1, *p2, 1, 2);
    if (w1 < 0) side(*p2, *p0, 2, 0);
  }
  detail::finish_point_triangle(r, p, a, b, c);
  return r;
}

}  // namespace crumple::geometry
