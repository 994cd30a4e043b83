#include <crumple/geometry/kernel_batch.hpp>

#include <crumple/geometry/predicates.hpp>
#include <crumple/geometry/triangle_intersection.hpp>

#include <immintrin.h>

#include <cmath>
#include <cstring>
#include <limits>

// The vector type's ABI differs with and without AVX, which GCC warns about at every function
// taking or returning one; all of those below are inlined into segment_segment_x4.
#pragma GCC diagnostic ignored "-Wpsabi"

namespace crumple::geometry {

namespace {

// Four doubles, and the masks that comparing them gives (all bits set where true), as GCC's
// vector extensions; compiled with AVX2 only (segment_segment_x4), where they are one
// register each.
using V = Scalar __attribute__((vector_size(32)));
using M = long long __attribute__((vector_size(32)));

// Every helper is compiled for AVX2 too (the square root is an AVX intrinsic) and inlined.
#define CRUMPLE_LANES inline __attribute__((always_inline, target("avx2")))

CRUMPLE_LANES V splat(Scalar x) { return V{x, x, x, x}; }
CRUMPLE_LANES V sqrt(V x) { return reinterpret_cast<V>(_mm256_sqrt_pd(reinterpret_cast<__m256d>(x))); }
CRUMPLE_LANES void store(std::array<Scalar, SegmentBatch::kLanes>& to, V x) { std::memcpy(to.data(), &x, sizeof(V)); }
CRUMPLE_LANES V select(M m, V yes, V no) { return m ? yes : no; }
// Row k of a batch's coordinates, read where it is (an array of the rows, filled first, was the
// batch copied to the stack and read back: a sixth of the edge-edge kernel's time).
CRUMPLE_LANES V load_row(const std::array<Scalar, SegmentBatch::kLanes>& row) {
  return reinterpret_cast<V>(_mm256_loadu_pd(row.data()));
}
CRUMPLE_LANES V row(const SegmentBatch& batch, std::size_t k) { return load_row(batch.coords[k]); }
CRUMPLE_LANES M select(M m, M yes, M no) { return (m & yes) | (~m & no); }

// The scalar kernel's helpers, lane by lane (distance_impl.hpp).
// x.dot(y) of Eigen's fixed-size 3-vectors, summed in the order of Eigen's unrolled reduction
// (the tests check it bit for bit).
CRUMPLE_LANES V dot(const V (&x)[3], const V (&y)[3]) { return x[0] * y[0] + x[1] * y[1] + x[2] * y[2]; }
// std::clamp(x, 0, 1).
CRUMPLE_LANES V clamp01(V x) {
  const V zero = splat(0), one = splat(1);
  return select(x < zero, zero, select(one < x, one, x));
}
// detail::clamped_root(slope, h0, h1).
CRUMPLE_LANES V clamped_root(V slope, V h0, V h1) {
  const V zero = splat(0), one = splat(1);
  const V r = -h0 / slope;
  return select(h0 >= zero, zero, select(h1 <= zero, one, select(r < one, r, one)));
}

// The scalar kernel (distance_impl.hpp) on four lanes: every branch evaluated, each lane's
// outcome selected, in the scalar kernel's order of operations.
CRUMPLE_LANES SegmentBatchResult run(const SegmentBatch& batch) {
  V u[3], v[3], w[3];
  for (std::size_t i = 0; i < 3; ++i) {
    u[i] = row(batch, 3 + i) - row(batch, i);
    v[i] = row(batch, 9 + i) - row(batch, 6 + i);
    w[i] = row(batch, i) - row(batch, 6 + i);
  }
  const V a = dot(u, u), b = dot(u, v), c = dot(v, v), d = dot(u, w), e = dot(v, w);
  const V zero = splat(0), one = splat(1);

  const V f00 = d, f10 = d + a, f01 = d - b, f11 = f10 - b;
  const V g00 = -e, g10 = -b - e, g01 = c - e, g11 = g10 + c;
  const V s_at_t0 = clamped_root(a, f00, f10);
  const V s_at_t1 = clamped_root(a, f01, f11);
  // k = -1, 0, 1 of the scalar kernel as two masks: low (<= 0) and high (>= 1).
  const M low0 = s_at_t0 <= zero, high0 = ~low0 & (s_at_t0 >= one);
  const M low1 = s_at_t1 <= zero, high1 = ~low1 & (s_at_t1 >= one);
  // The minimisers of G along the edges s = 0 and s = 1.
  const V t_s0 = clamped_root(c, g00, g01);
  const V t_s1 = clamped_root(c, g10, g11);

  // The F = 0 line's ends E0 (from k0) and E1 (from k1): on s = 0 for k = -1, on s = 1 for
  // k = 1, else on t = 0 (E0) or t = 1 (E1).
  const V t_on_s0 = clamp01(f00 / b), t_on_s1 = clamp01(f10 / b);
  const V s_e0 = select(low0, zero, select(high0, one, s_at_t0));
  const V t_e0 = select(low0, t_on_s0, select(high0, t_on_s1, zero));
  const V s_e1 = select(low1, zero, select(high1, one, s_at_t1));
  const V t_e1 = select(low1, t_on_s0, select(high1, t_on_s1, one));
  const V ba = b / a, da = d / a;
  V v_perp[3], w_perp[3];
  for (std::size_t i = 0; i < 3; ++i) {
    v_perp[i] = v[i] - ba * u[i];
    w_perp[i] = w[i] - da * u[i];
  }
  const V g_slope = dot(v_perp, v_perp), g_offset = dot(v_perp, w_perp);
  const V dt = t_e1 - t_e0;
  const V h0 = dt * (g_slope * t_e0 - g_offset);
  const V h1 = dt * (g_slope * t_e1 - g_offset);
  const V z = clamp01(h0 / (h0 - h1));
  const V omz = one - z;
  const V s_in = clamp01(omz * s_e0 + z * s_e1);
  const V t_in = clamp01(omz * t_e0 + z * t_e1);
  // An end point on s = 0 or s = 1 slides along that edge; on t = 0 or 1 it stays.
  const V s_end0 = s_e0, t_end0 = select(low0, t_s0, select(high0, t_s1, t_e0));
  const V s_end1 = s_e1, t_end1 = select(low1, t_s0, select(high1, t_s1, t_e1));
  const M at_e0 = h0 >= zero, at_e1 = ~at_e0 & (h1 <= zero);
  V s = select(at_e0, s_end0, select(at_e1, s_end1, s_in));
  V t = select(at_e0, t_end0, select(at_e1, t_end1, t_in));
  // Both ends of the line on the same edge s = 0 (s = 1): minimise G along it.
  const M both_low = low0 & low1, both_high = high0 & high1;
  s = select(both_low, zero, select(both_high, one, s));
  t = select(both_low, t_s0, select(both_high, t_s1, t));
  // A point segment (a = 0 or c = 0).
  const M a_pos = a > zero, c_pos = c > zero;
  s = select(a_pos & c_pos, s, select(a_pos, s_at_t0, zero));
  t = select(a_pos & c_pos, t, select(c_pos, t_s0, zero));

  V r[3];
  for (std::size_t i = 0; i < 3; ++i) r[i] = w[i] + s * u[i] - t * v[i];
  const V sqr = dot(r, r);
  SegmentBatchResult out;
  store(out.sqr_distance, sqr);
  store(out.s, s);
  store(out.t, t);

  // What a contact is made of (segment_segment's closest points, then
  // narrow::edge_edge_contact): the distance, and the unit vector between the closest points
  // (Eigen's norm() is the square root of squaredNorm(), its division by a scalar one per
  // coordinate).
  store(out.distance, sqrt(sqr));
  const M s_one = s == one, t_one = t == one;
  V gap[3];
  for (std::size_t i = 0; i < 3; ++i) {
    const V closest0 = select(s_one, row(batch, 3 + i), row(batch, i) + s * u[i]);
    const V closest1 = select(t_one, row(batch, 9 + i), row(batch, 6 + i) + t * v[i]);
    gap[i] = closest1 - closest0;
  }
  const V gap_norm = sqrt(dot(gap, gap));
  store(out.gap_norm, gap_norm);
  for (std::size_t i = 0; i < 3; ++i) store(out.normal[i], gap[i] / gap_norm);
  return out;
}

// Three lanes of coordinates: a 3-vector for each of the four pairs.
struct V3 {
  V c[3];
};
// Point `point` of every pair of the batch.
template <std::size_t Points>
CRUMPLE_LANES V3 load(const PointBatch<Points>& batch, std::size_t point) {
  V3 out;
  for (std::size_t i = 0; i < 3; ++i) out.c[i] = load_row(batch.coords[3 * point + i]);
  return out;
}
CRUMPLE_LANES V3 operator-(const V3& x, const V3& y) { return {{x.c[0] - y.c[0], x.c[1] - y.c[1], x.c[2] - y.c[2]}}; }
CRUMPLE_LANES V3 operator+(const V3& x, const V3& y) { return {{x.c[0] + y.c[0], x.c[1] + y.c[1], x.c[2] + y.c[2]}}; }
CRUMPLE_LANES V3 operator*(V k, const V3& x) { return {{k * x.c[0], k * x.c[1], k * x.c[2]}}; }
CRUMPLE_LANES V dot(const V3& x, const V3& y) { return dot(x.c, y.c); }
CRUMPLE_LANES V3 select(M m, const V3& yes, const V3& no) {
  return {{select(m, yes.c[0], no.c[0]), select(m, yes.c[1], no.c[1]), select(m, yes.c[2], no.c[2])}};
}
// The first of (x0 where m0, x1 where m1, x2 otherwise): a choice among three, lane by lane.
template <class T>
CRUMPLE_LANES T choose(M m0, M m1, const T& x0, const T& x1, const T& x2) {
  return select(m0, x0, select(m1, x1, x2));
}

// point_segment(p, from, to), lane by lane: its parameter t, closest point and squared
// distance.
struct SideResult {
  V t, sqr;
  V3 closest;
};
CRUMPLE_LANES SideResult point_segment(const V3& p, const V3& from, const V3& to) {
  const V zero = splat(0), one = splat(1);
  const V3 u = to - from, ap = p - from;
  const V num = dot(ap, u), den = dot(u, u);
  // detail::clamped_ratio(num, den).
  const V t = select(num <= zero, zero, select(num >= den, one, num / den));
  const M at_end = t == one;
  const V3 to_p = p - to, off = ap - t * u;
  return {t, select(at_end, dot(to_p, to_p), dot(off, off)), select(at_end, to, from + t * u)};
}

// The side answer kept so far: squared distance, closest point, barycentrics (P0, P1, P2).
struct Best {
  V sqr;
  V3 closest, w;
};
// Side (from, to) of the triangle, corners i_from and i_to, where `active`: replaces `best` where
// strictly closer.
CRUMPLE_LANES void try_side(Best& best, M active, const V3& p, const V3& from, const V3& to, std::size_t i_from,
                            std::size_t i_to) {
  const V zero = splat(0), one = splat(1);
  const SideResult r = point_segment(p, from, to);
  const M take = active & (r.sqr < best.sqr);
  best.sqr = select(take, r.sqr, best.sqr);
  best.closest = select(take, r.closest, best.closest);
  V3 side_w{{zero, zero, zero}};
  side_w.c[i_from] = one - r.t;
  side_w.c[i_to] = r.t;
  best.w = select(take, side_w, best.w);
}

// The scalar point_triangle (distance_impl.hpp) on four lanes, with the contact's distance and
// normal (narrow::vertex_face). Lanes whose triangle the scalar kernel treats as degenerate
// (corners coincident, or flat) are marked in `degenerate` and left to the scalar kernel.
CRUMPLE_LANES PointTriangleBatchResult run_point_triangle(const PointTriangleBatch& batch, M& degenerate) {
  const V zero = splat(0), one = splat(1);
  const V3 p = load(batch, 0), a = load(batch, 1), b = load(batch, 2), c = load(batch, 3);
  const V3 ab = b - a, bc = c - b, ca = a - c;
  const V lab = dot(ab, ab), lbc = dot(bc, bc), lca = dot(ca, ca);
  // The base P0 -> P1 is the longest side: rotation 0 (a b c), 1 (b c a) or 2 (c a b).
  const M rot0 = (lab >= lbc) & (lab >= lca), rot1 = ~rot0 & (lbc >= lca);
  const V3 p0 = choose(rot0, rot1, a, b, c), p1 = choose(rot0, rot1, b, c, a), p2 = choose(rot0, rot1, c, a, b);
  const V3 e = choose(rot0, rot1, ab, bc, ca);
  const V l2 = choose(rot0, rot1, lab, lbc, lca);
  const V3 rv = p2 - p0, q = p - p0;
  const V inv_l2 = one / l2;
  const V x_r = dot(rv, e) * inv_l2;
  const V3 r_perp = rv - x_r * e;
  const V h2 = dot(r_perp, r_perp);
  degenerate = ~(l2 > zero) | ~(h2 > splat(detail::kFlatRatio) * l2);

  const V x_q = dot(q, e) * inv_l2;
  const V3 q_perp = q - x_q * e;
  const V y = dot(q_perp, r_perp) / h2;
  const V w2 = y, w1 = x_q - y * x_r, w0 = one - w1 - w2;
  const M inside = (w0 >= zero) & (w1 >= zero) & (w2 >= zero);
  // Region 0: the foot.
  const V3 offset = x_q * e + y * r_perp;
  const V3 foot_gap = q - offset;
  V sqr = dot(foot_gap, foot_gap);
  V3 closest = p0 + offset;
  V3 w{{w0, w1, w2}};  // barycentrics for (P0, P1, P2)
  // Elsewhere: the best of the sides opposite a negative w, in the scalar kernel's order (a
  // later side replaces an earlier one only when strictly closer).
  Best best{splat(std::numeric_limits<Scalar>::infinity()), closest, w};
  try_side(best, w2 < zero, p, p0, p1, 0, 1);
  try_side(best, w0 < zero, p, p1, p2, 1, 2);
  try_side(best, w1 < zero, p, p2, p0, 2, 0);
  sqr = select(inside, sqr, best.sqr);
  closest = select(inside, closest, best.closest);
  w = select(inside, w, best.w);
  // Barycentrics for (a, b, c).
  const V3 bary{{choose(rot0, rot1, w.c[0], w.c[2], w.c[1]), choose(rot0, rot1, w.c[1], w.c[0], w.c[2]),
                 choose(rot0, rot1, w.c[2], w.c[1], w.c[0])}};
  // detail::finish_point_triangle: a corner answer is that corner exactly.
  const M z0 = bary.c[0] == zero, z1 = bary.c[1] == zero, z2 = bary.c[2] == zero;
  const M at_a = z1 & z2, at_b = ~at_a & z0 & z2, at_c = ~at_a & ~at_b & z0 & z1;
  const M at_corner = at_a | at_b | at_c;
  const V3 corner = choose(at_a, at_b, a, b, c);
  const V3 corner_gap = corner - p;
  sqr = select(at_corner, dot(corner_gap, corner_gap), sqr);
  closest = select(at_corner, corner, closest);

  PointTriangleBatchResult out;
  store(out.sqr_distance, sqr);
  for (std::size_t i = 0; i < 3; ++i) store(out.barycentric[i], bary.c[i]);
  store(out.distance, sqrt(sqr));
  const V3 away = p - closest;
  const V away_norm = sqrt(dot(away, away));
  store(out.away_norm, away_norm);
  for (std::size_t i = 0; i < 3; ++i) store(out.normal[i], away.c[i] / away_norm);
  return out;
}

// Orientation determinants whose sign the floating-point filter decides: where `pos` (`neg`) is
// set, the exact sign is +1 (-1); where neither, the filter cannot tell (the scalar predicate
// would go on to the exact expansion).
struct Signs {
  M pos, neg;
};
CRUMPLE_LANES V magnitude(V x) { return reinterpret_cast<V>(reinterpret_cast<M>(x) & ~reinterpret_cast<M>(splat(-0.0))); }
// detail::orient3d_sign's filter.
CRUMPLE_LANES Signs certain(V det, V permanent) {
  const V bound = splat(detail::kOrient3dBound) * permanent;
  return {det > bound, -det > bound};
}
// orient3d(a, b, c, d) with its evaluation and filter (predicates.hpp), lane by lane.
CRUMPLE_LANES Signs orient(const V3& a, const V3& b, const V3& c, const V3& d) {
  const V3 u = b - a, v = c - a, w = d - a;
  const V vywz = v.c[1] * w.c[2], vzwy = v.c[2] * w.c[1];
  const V vzwx = v.c[2] * w.c[0], vxwz = v.c[0] * w.c[2];
  const V vxwy = v.c[0] * w.c[1], vywx = v.c[1] * w.c[0];
  const V det = u.c[0] * (vywz - vzwy) + u.c[1] * (vzwx - vxwz) + u.c[2] * (vxwy - vywx);
  const V permanent = magnitude(u.c[0]) * (magnitude(vywz) + magnitude(vzwy)) +
                      magnitude(u.c[1]) * (magnitude(vzwx) + magnitude(vxwz)) +
                      magnitude(u.c[2]) * (magnitude(vxwy) + magnitude(vywx));
  return certain(det, permanent);
}
// orient3d_sides(a, b, c, d[0], d[1], d[2]) with its evaluation and filter, lane by lane.
CRUMPLE_LANES std::array<Signs, 3> plane_sides(const V3& a, const V3& b, const V3& c, const V3& d0, const V3& d1,
                                               const V3& d2) {
  const V3 u = b - a, v = c - a;
  const V uyvz = u.c[1] * v.c[2], uzvy = u.c[2] * v.c[1];
  const V uzvx = u.c[2] * v.c[0], uxvz = u.c[0] * v.c[2];
  const V uxvy = u.c[0] * v.c[1], uyvx = u.c[1] * v.c[0];
  const V3 m{{uyvz - uzvy, uzvx - uxvz, uxvy - uyvx}};
  const V3 pm{{magnitude(uyvz) + magnitude(uzvy), magnitude(uzvx) + magnitude(uxvz), magnitude(uxvy) + magnitude(uyvx)}};
  std::array<Signs, 3> out;
  const V3* d[3] = {&d0, &d1, &d2};
  for (std::size_t k = 0; k < 3; ++k) {
    const V3 w = *d[k] - a;
    out[k] = certain(w.c[0] * m.c[0] + w.c[1] * m.c[1] + w.c[2] * m.c[2],
                     magnitude(w.c[0]) * pm.c[0] + magnitude(w.c[1]) * pm.c[1] + magnitude(w.c[2]) * pm.c[2]);
  }
  return out;
}
// A triangle's corners (p, q, r) rotated so that p is the corner alone on its side of the other
// triangle's plane (sides s, all certain and not all equal), and whether p lies below it.
struct Rotated {
  V3 p, q, r;
  M below;
};
CRUMPLE_LANES Rotated rotate_alone(const V3& x0, const V3& x1, const V3& x2, const std::array<Signs, 3>& s) {
  // triangles_intersect's `alone`: corner 2 if s0 == s1, else corner 1 if s0 == s2, else 0.
  const M alone2 = ~(s[0].pos ^ s[1].pos), alone1 = ~(s[0].pos ^ s[2].pos);
  return {choose(alone2, alone1, x2, x1, x0), choose(alone2, alone1, x0, x2, x1), choose(alone2, alone1, x1, x0, x2),
          choose(alone2, alone1, s[2].neg, s[1].neg, s[0].neg)};
}

// triangles_intersect on four lanes, where the filters decide: the mask of the lanes found
// intersecting, and in `deferred` those that need the exact predicates.
CRUMPLE_LANES M run_triangles(const TrianglePairBatch& batch, M& deferred) {
  const V3 a0 = load(batch, 0), a1 = load(batch, 1), a2 = load(batch, 2);
  const V3 b0 = load(batch, 3), b1 = load(batch, 4), b2 = load(batch, 5);
  // Step 1, the plane rejection: the corners of one triangle certainly all on one side of the
  // other's plane.
  const std::array<Signs, 3> sb = plane_sides(a0, a1, a2, b0, b1, b2);
  const std::array<Signs, 3> sa = plane_sides(b0, b1, b2, a0, a1, a2);
  const M apart = (sb[0].pos & sb[1].pos & sb[2].pos) | (sb[0].neg & sb[1].neg & sb[2].neg) |
                  (sa[0].pos & sa[1].pos & sa[2].pos) | (sa[0].neg & sa[1].neg & sa[2].neg);
  M all_certain = ~M{};
  for (std::size_t k = 0; k < 3; ++k) all_certain &= (sa[k].pos | sa[k].neg) & (sb[k].pos | sb[k].neg);
  // Not apart, with every sign certain (none zero): each triangle strictly straddles the other's
  // plane. Guigue and Devillers' two orientations, as in triangles_intersect: p1 above the
  // second triangle's plane by swapping its last two corners where p1 lies below, and likewise.
  const Rotated ra = rotate_alone(a0, a1, a2, sa), rb = rotate_alone(b0, b1, b2, sb);
  const V3 q2 = select(ra.below, rb.r, rb.q), r2 = select(ra.below, rb.q, rb.r);
  const V3 q1 = select(rb.below, ra.r, ra.q), r1 = select(rb.below, ra.q, ra.r);
  const Signs o1 = orient(ra.p, q1, rb.p, q2), o2 = orient(ra.p, r1, r2, rb.p);
  const M straddling = all_certain & ~apart;
  const M hit = straddling & o1.neg & o2.neg;
  const M miss = straddling & (o1.pos | o2.pos);
  deferred = ~(apart | hit | miss);
  return hit;
}

#undef CRUMPLE_LANES

}  // namespace

bool has_avx2() {
  static const bool yes = [] {
    __builtin_cpu_init();  // in case the first call comes before libgcc's own initialisation
    return __builtin_cpu_supports("avx2") != 0;
  }();
  return yes;
}

__attribute__((target("avx2"))) SegmentBatchResult segment_segment_x4(const SegmentBatch& batch) {
  return run(batch);
}

__attribute__((target("avx2"))) PointTriangleBatchResult point_triangle_x4(const PointTriangleBatch& batch) {
  M degenerate;
  PointTriangleBatchResult out = run_point_triangle(batch, degenerate);
  for (std::size_t k = 0; k < PointTriangleBatch::kLanes; ++k) {
    if (degenerate[k] == 0) continue;
    const Vec3 p = batch.get(k, 0);
    const PointTriangleResult r = point_triangle(p, batch.get(k, 1), batch.get(k, 2), batch.get(k, 3));
    const Vec3 away = p - r.closest;
    const Scalar away_norm = away.norm();
    out.sqr_distance[k] = r.sqr_distance;
    out.distance[k] = std::sqrt(r.sqr_distance);
    out.away_norm[k] = away_norm;
    for (std::size_t i = 0; i < 3; ++i) {
      out.barycentric[i][k] = r.barycentric[static_cast<Eigen::Index>(i)];
      out.normal[i][k] = away[static_cast<Eigen::Index>(i)] / away_norm;
    }
  }
  return out;
}

__attribute__((target("avx2"))) unsigned triangles_intersect_x4(const TrianglePairBatch& batch, std::size_t count,
                                                                unsigned* deferred) {
  M undecided;
  const M hit = run_triangles(batch, undecided);
  const unsigned used = (1u << count) - 1;
  unsigned hits = static_cast<unsigned>(_mm256_movemask_pd(reinterpret_cast<__m256d>(hit))) & used;
  const unsigned exact = static_cast<unsigned>(_mm256_movemask_pd(reinterpret_cast<__m256d>(undecided))) & used;
  for (std::size_t k = 0; k < count; ++k) {
    if ((exact >> k & 1u) == 0) continue;
    if (triangles_intersect(batch.get(k, 0), batch.get(k, 1), batch.get(k, 2), batch.get(k, 3), batch.get(k, 4),
                            batch.get(k, 5))) {
      hits |= 1u << k;
    }
  }
  if (deferred != nullptr) *deferred = exact;
  return hits;
}

}  // namespace crumple::geometry
