#include <crumple/geometry/segment_batch.hpp>

#include <immintrin.h>

#include <cstring>

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
  V x[12];
  for (std::size_t k = 0; k < 12; ++k) std::memcpy(&x[k], batch.coords[k].data(), sizeof(V));
  V u[3], v[3], w[3];
  for (std::size_t i = 0; i < 3; ++i) {
    u[i] = x[3 + i] - x[i];
    v[i] = x[9 + i] - x[6 + i];
    w[i] = x[i] - x[6 + i];
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

  // What a contact is made of (set_closest_points, then narrow::edge_edge_contact): the
  // distance, and the unit vector between the closest points (Eigen's norm() is the square
  // root of squaredNorm(), its division by a scalar one per coordinate).
  store(out.distance, sqrt(sqr));
  const M s_one = s == one, t_one = t == one;
  V gap[3];
  for (std::size_t i = 0; i < 3; ++i) {
    const V closest0 = select(s_one, x[3 + i], x[i] + s * u[i]);
    const V closest1 = select(t_one, x[9 + i], x[6 + i] + t * v[i]);
    gap[i] = closest1 - closest0;
  }
  const V gap_norm = sqrt(dot(gap, gap));
  store(out.gap_norm, gap_norm);
  for (std::size_t i = 0; i < 3; ++i) store(out.normal[i], gap[i] / gap_norm);
  return out;
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

}  // namespace crumple::geometry
