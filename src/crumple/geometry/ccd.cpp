#include <crumple/geometry/ccd.hpp>

#include <crumple/core/error.hpp>
#include <crumple/geometry/ccd_detail.hpp>
#include <crumple/geometry/distance.hpp>
#include <crumple/geometry/kernel_batch.hpp>

#include <immintrin.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <queue>
#include <vector>

// The lanes' vector type has a different ABI with and without AVX, which GCC warns about at
// every function taking or returning one; all of those are inlined into the two kernels.
#pragma GCC diagnostic ignored "-Wpsabi"

// Inlining only, the same operations: under the sanitizers GCC's flatten inlines every
// instrumented callee recursively, and this file alone took over 14 CPU minutes to compile.
#if defined(CRUMPLE_SANITIZED)
#define CRUMPLE_CCD_FLATTEN
#else
#define CRUMPLE_CCD_FLATTEN __attribute__((flatten))
#endif

namespace crumple::geometry {

namespace {

/// Unit roundoff of binary64.
constexpr Scalar kU = 0x1p-53;
/// Corner-evaluation error factor: the evaluation order below needs 30 u (+ O(u²)); 64 u
/// leaves a factor of two (docs/ccd.md).
constexpr Scalar kCornerErrorFactor = 64 * kU;
/// Absolute term covering underflow: each of the few dozen roundings of a value may err by up
/// to 2^-1075 beyond the relative model when its result is subnormal.
constexpr Scalar kUnderflowSlack = 0x1p-1000;
/// Inputs above this magnitude (or non-finite) get a conservative hit: sums of 6 differences
/// must not overflow.
constexpr Scalar kMaxMagnitude = 0x1p1000;
/// The coplanarity filter multiplies three differences: it runs only below this magnitude.
constexpr Scalar kMaxSignFilterMagnitude = 0x1p300;
/// Queries whose largest coordinate lies outside [this, kMaxUnscaledMagnitude] are computed
/// scaled by a power of two (when that is exact).
constexpr Scalar kMinUnscaledMagnitude = 0x1p-300;
constexpr Scalar kMaxUnscaledMagnitude = 0x1p300;
/// Smallest box width that is split again. Keeps every u and v bound a dyadic rational with at
/// most 40 fractional bits, so midpoints and u + v are exact in binary64. (t bounds start at the
/// advancement's time, any double: 1 - t and the t midpoints may round; docs/ccd.md.)
constexpr Scalar kMinWidth = 0x1p-40;

/// F(t, u, v) = (1 - t) G⁰(u, v) + t G¹(u, v) with G^τ(u, v) = a^τ + u b^τ + v c^τ: for VF the
/// vertex minus the triangle's point, for EE edge a's point minus edge b's point.
struct Prepared {
  std::array<Vec3, 2> a, b, c;
  Vec3 bound;  // err + δ, rounded up, per axis
  Vec3 err;
  Scalar delta = 0;
  Scalar delta2_up = 0;  // ≥ (δ · square)²
  /// A power of two that the squared-length tests (witness, δ rejection) multiply lengths by
  /// before squaring: 1 for magnitudes in [2^-300, 2^300], else 2^-ilogb(magnitude), so the
  /// squares neither overflow (inf <= inf made every corner a witness) nor underflow. Exact:
  /// scaling by a power of two commutes with rounding away from overflow and underflow.
  Scalar square = 1;
  bool face = false;
};

/// Rounds a positive sum of a few terms up enough to dominate its exact value.
Scalar round_up(Scalar x) { return x * (1 + 0x1p-50) + kUnderflowSlack; }

Vec3 max_abs_coordinates(const CcdPoints& start, const CcdPoints& end) {
  Vec3 m = Vec3::Zero();
  for (int i = 0; i < 4; ++i) {
    m = m.cwiseMax(start[i].cwiseAbs()).cwiseMax(end[i].cwiseAbs());
  }
  return m;
}

bool in_range(const CcdPoints& start, const CcdPoints& end) {
  for (int i = 0; i < 4; ++i) {
    for (int k = 0; k < 3; ++k) {
      // !(x <= max) is true for NaN too.
      if (!(std::abs(start[i][k]) <= kMaxMagnitude) || !(std::abs(end[i][k]) <= kMaxMagnitude)) {
        return false;
      }
    }
  }
  return true;
}

/// err of one axis from its largest |coordinate| `m` (monotone in m).
Scalar axis_error(Scalar m) { return kCornerErrorFactor * m + kUnderflowSlack; }

/// err and the hull bound from the largest |coordinate| per axis `m`; `ccd_hull_bound` is the
/// same expression (so it dominates this one for any larger magnitude).
void set_bounds(Prepared& p, const Vec3& m, Scalar delta) {
  for (int k = 0; k < 3; ++k) {
    p.err[k] = axis_error(m[k]);
    p.bound[k] = round_up(p.err[k] + delta);
  }
  p.delta = delta;
  const Scalar magnitude = m.maxCoeff();
  if (magnitude > 0x1p300 || (magnitude > 0 && magnitude < 0x1p-300)) {
    p.square = std::ldexp(Scalar(1), -std::ilogb(magnitude));
  }
  p.delta2_up = round_up((delta * p.square) * (delta * p.square));
}

/// The differences a, b, c at t = 0 and t = 1 (after set_bounds).
void prepare(Prepared& p, CcdPair pair, const CcdPoints& start, const CcdPoints& end) {
  p.face = pair == CcdPair::kVertexFace;
  for (int tau = 0; tau < 2; ++tau) {
    const CcdPoints& x = tau == 0 ? start : end;
    if (p.face) {
      p.a[tau] = x[0] - x[1];  // vertex - f0
      p.b[tau] = x[1] - x[2];  // -(f1 - f0)
      p.c[tau] = x[1] - x[3];  // -(f2 - f0)
    } else {
      p.a[tau] = x[0] - x[2];  // a0 - b0
      p.b[tau] = x[1] - x[0];  // a1 - a0
      p.c[tau] = x[2] - x[3];  // -(b1 - b0)
    }
  }
}

/// Filter 1: F over the whole domain lies in the convex hull of the difference points at
/// t = 0 and t = 1 (VF: vertex - triangle corner, 6 points; EE: a_i - b_j, 8 points). Each is one
/// rounded subtraction, error ≤ 2 u max|coord| ≤ err. Returns false when some axis separates the
/// hull from [-bound, bound]; `extent` receives the largest |coordinate| of the points.
struct Hull {
  std::array<Vec3, 8> points;
  int count = 0;
};

bool hull_may_touch(CcdPair pair, const CcdPoints& start, const CcdPoints& end, const Vec3& bound,
                    Scalar& extent, Hull& hull) {
  Vec3 lo = Vec3::Constant(INFINITY);
  Vec3 hi = Vec3::Constant(-INFINITY);
  const auto add = [&](const Vec3& d) {
    lo = lo.cwiseMin(d);
    hi = hi.cwiseMax(d);
    hull.points[hull.count++] = d;
  };
  for (const CcdPoints* x : {&start, &end}) {
    const CcdPoints& q = *x;
    if (pair == CcdPair::kVertexFace) {
      add(q[0] - q[1]);
      add(q[0] - q[2]);
      add(q[0] - q[3]);
    } else {
      add(q[0] - q[2]);
      add(q[0] - q[3]);
      add(q[1] - q[2]);
      add(q[1] - q[3]);
    }
  }
  extent = std::max(lo.cwiseAbs().maxCoeff(), hi.cwiseAbs().maxCoeff());
  for (int k = 0; k < 3; ++k) {
    if (lo[k] > bound[k] || hi[k] < -bound[k]) return false;
  }
  return true;
}

/// `hull_may_touch`'s rejection, decided with one four-double vector per point (x, y, z, and a
/// spare lane holding another coordinate of the query): true only for a query whose every
/// |coordinate| is at most 2^300 (NaN fails the comparison) and whose largest is at least
/// 2^-300, so that `ccd_checked` neither scales it nor answers it out of range, and only when
/// `hull_may_touch` on it returns false. Its values are the scalar ones bit for bit: the
/// per-axis maxima of |coordinate| and the minima and maxima of the differences are extremes of
/// finite values (independent of the order they are taken in), the differences are the same
/// single roundings, and err and the bound are the same expressions (set_bounds: a multiply and
/// an add each, no contraction). The spare lane never decides.
__attribute__((target("avx2"))) bool hull_apart_avx2(CcdPair pair, const CcdPoints& start, const CcdPoints& end,
                                                     Scalar delta) {
  static_assert(sizeof(CcdPoints) == 12 * sizeof(Scalar), "CcdPoints: 12 contiguous doubles");
  __m256d x[8];
  for (int tau = 0; tau < 2; ++tau) {
    const Scalar* d = reinterpret_cast<const Scalar*>((tau == 0 ? start : end).data());
    __m256d* q = x + 4 * tau;
    q[0] = _mm256_loadu_pd(d);      // x0 y0 z0 | x1
    q[1] = _mm256_loadu_pd(d + 3);  // x1 y1 z1 | x2
    q[2] = _mm256_loadu_pd(d + 6);  // x2 y2 z2 | x3
    q[3] = _mm256_permute4x64_pd(_mm256_loadu_pd(d + 8), 0x39);  // z2 x3 y3 z3 -> x3 y3 z3 | z2
  }
  const __m256d sign = _mm256_set1_pd(-0.0);
  const __m256d limit = _mm256_set1_pd(kMaxUnscaledMagnitude);
  __m256d m = _mm256_andnot_pd(sign, x[0]);
  __m256d in = _mm256_cmp_pd(m, limit, _CMP_LE_OQ);
  for (int i = 1; i < 8; ++i) {
    const __m256d a = _mm256_andnot_pd(sign, x[i]);
    m = _mm256_max_pd(m, a);
    in = _mm256_and_pd(in, _mm256_cmp_pd(a, limit, _CMP_LE_OQ));
  }
  // Every lane holds coordinates of the query only, so the largest lane is its largest |coordinate|.
  if (_mm256_movemask_pd(in) != 0xF ||
      _mm256_movemask_pd(_mm256_cmp_pd(m, _mm256_set1_pd(kMinUnscaledMagnitude), _CMP_GE_OQ)) == 0) {
    return false;
  }
  const __m256d err = _mm256_add_pd(_mm256_mul_pd(_mm256_set1_pd(kCornerErrorFactor), m), _mm256_set1_pd(kUnderflowSlack));
  const __m256d bound = _mm256_add_pd(_mm256_mul_pd(_mm256_add_pd(err, _mm256_set1_pd(delta)), _mm256_set1_pd(1 + 0x1p-50)),
                                      _mm256_set1_pd(kUnderflowSlack));
  // The differences: VF p - f_i (points 0 - 1, 2, 3), EE a_i - b_j (0, 1 - 2, 3), per time.
  const bool face = pair == CcdPair::kVertexFace;
  __m256d lo = _mm256_sub_pd(x[0], x[face ? 1 : 2]);
  __m256d hi = lo;
  for (int tau = 0; tau < 2; ++tau) {
    const __m256d* q = x + 4 * tau;
    const __m256d d[4] = {_mm256_sub_pd(q[0], q[face ? 1 : 2]), _mm256_sub_pd(q[0], q[face ? 2 : 3]),
                          _mm256_sub_pd(q[face ? 0 : 1], q[face ? 3 : 2]), _mm256_sub_pd(q[1], q[3])};
    for (int i = 0; i < (face ? 3 : 4); ++i) {
      lo = _mm256_min_pd(lo, d[i]);
      hi = _mm256_max_pd(hi, d[i]);
    }
  }
  const __m256d apart = _mm256_or_pd(_mm256_cmp_pd(lo, bound, _CMP_GT_OQ),
                                     _mm256_cmp_pd(hi, _mm256_xor_pd(bound, sign), _CMP_LT_OQ));
  return (_mm256_movemask_pd(apart) & 0x7) != 0;
}

/// hull_apart_avx2 for four queries at once, one per lane (bit l of the result for
/// `q[l]`): the same values per lane (the maxima and minima of finite values in another order,
/// the same differences and bound expressions), so the same answers.
__attribute__((target("avx2"))) unsigned hull_apart_x4(CcdPair pair, const CcdQuery* q, Scalar delta) {
  static_assert(sizeof(CcdQuery) == 24 * sizeof(Scalar), "CcdQuery: 24 contiguous doubles");
  // c[12 τ + 3 i + k]: coordinate k of point i at time τ, one query per lane (4 × 4 transposes).
  __m256d c[24];
  for (int j = 0; j < 6; ++j) {
    const __m256d r0 = _mm256_loadu_pd(reinterpret_cast<const Scalar*>(q + 0) + 4 * j);
    const __m256d r1 = _mm256_loadu_pd(reinterpret_cast<const Scalar*>(q + 1) + 4 * j);
    const __m256d r2 = _mm256_loadu_pd(reinterpret_cast<const Scalar*>(q + 2) + 4 * j);
    const __m256d r3 = _mm256_loadu_pd(reinterpret_cast<const Scalar*>(q + 3) + 4 * j);
    const __m256d a = _mm256_unpacklo_pd(r0, r1), b = _mm256_unpackhi_pd(r0, r1);  // r0[0] r1[0] r0[2] r1[2] ...
    const __m256d e = _mm256_unpacklo_pd(r2, r3), f = _mm256_unpackhi_pd(r2, r3);
    c[4 * j + 0] = _mm256_permute2f128_pd(a, e, 0x20);
    c[4 * j + 1] = _mm256_permute2f128_pd(b, f, 0x20);
    c[4 * j + 2] = _mm256_permute2f128_pd(a, e, 0x31);
    c[4 * j + 3] = _mm256_permute2f128_pd(b, f, 0x31);
  }
  const __m256d sign = _mm256_set1_pd(-0.0);
  const __m256d limit = _mm256_set1_pd(kMaxUnscaledMagnitude);
  __m256d in = _mm256_castsi256_pd(_mm256_set1_epi64x(-1));
  __m256d m[3];
  for (int k = 0; k < 3; ++k) {
    m[k] = _mm256_setzero_pd();
    for (int i = 0; i < 8; ++i) {
      const __m256d a = _mm256_andnot_pd(sign, c[3 * i + k]);
      m[k] = _mm256_max_pd(m[k], a);
      in = _mm256_and_pd(in, _mm256_cmp_pd(a, limit, _CMP_LE_OQ));  // false for NaN
    }
  }
  const __m256d largest = _mm256_max_pd(_mm256_max_pd(m[0], m[1]), m[2]);
  in = _mm256_and_pd(in, _mm256_cmp_pd(largest, _mm256_set1_pd(kMinUnscaledMagnitude), _CMP_GE_OQ));
  const bool face = pair == CcdPair::kVertexFace;
  __m256d apart = _mm256_setzero_pd();
  for (int k = 0; k < 3; ++k) {
    const __m256d err = _mm256_add_pd(_mm256_mul_pd(_mm256_set1_pd(kCornerErrorFactor), m[k]), _mm256_set1_pd(kUnderflowSlack));
    const __m256d bound = _mm256_add_pd(
        _mm256_mul_pd(_mm256_add_pd(err, _mm256_set1_pd(delta)), _mm256_set1_pd(1 + 0x1p-50)), _mm256_set1_pd(kUnderflowSlack));
    __m256d lo = _mm256_sub_pd(c[k], c[3 * (face ? 1 : 2) + k]);
    __m256d hi = lo;
    for (int tau = 0; tau < 2; ++tau) {
      const __m256d* x = c + 12 * tau + k;  // x[3 i]: point i
      const __m256d d[4] = {_mm256_sub_pd(x[0], x[3 * (face ? 1 : 2)]), _mm256_sub_pd(x[0], x[3 * (face ? 2 : 3)]),
                            _mm256_sub_pd(x[3 * (face ? 0 : 1)], x[3 * (face ? 3 : 2)]), _mm256_sub_pd(x[3], x[9])};
      for (int i = 0; i < (face ? 3 : 4); ++i) {
        lo = _mm256_min_pd(lo, d[i]);
        hi = _mm256_max_pd(hi, d[i]);
      }
    }
    apart = _mm256_or_pd(apart, _mm256_or_pd(_mm256_cmp_pd(lo, bound, _CMP_GT_OQ),
                                             _mm256_cmp_pd(hi, _mm256_xor_pd(bound, sign), _CMP_LT_OQ)));
  }
  return static_cast<unsigned>(_mm256_movemask_pd(_mm256_and_pd(apart, in)));
}

/// Filter 3: a separating direction. For any vector n, F·n over the domain lies in the hull of
/// the difference points' projections. The computed projection of a point errs from the exact
/// one by at most Σ|n_k| err_k (the point's own rounding) + γ_3 Σ|d_k n_k| (the dot product);
/// all projections beyond δ‖n‖ plus that, on one side, prove ‖F‖ > δ everywhere.
bool separated_along(const Vec3& n, const Hull& hull, const Vec3& err, Scalar delta) {
  const Scalar nn = n.x() * n.x() + n.y() * n.y() + n.z() * n.z();
  if (!(nn > 0) || !std::isfinite(nn)) return false;
  Scalar lo = INFINITY, hi = -INFINITY, mag = 0;
  for (int i = 0; i < hull.count; ++i) {
    const Vec3& d = hull.points[i];
    const Scalar x = d.x() * n.x(), y = d.y() * n.y(), z = d.z() * n.z();
    const Scalar s = (x + y) + z;
    lo = std::min(lo, s);
    hi = std::max(hi, s);
    mag = std::max(mag, std::abs(x) + std::abs(y) + std::abs(z));
  }
  const Scalar slack = std::abs(n.x()) * err.x() + std::abs(n.y()) * err.y() + std::abs(n.z()) * err.z();
  const Scalar bound = (delta * std::sqrt(nn) + slack + 4 * kU * mag) * (1 + 16 * kU) + kUnderflowSlack;
  return lo > bound || hi < -bound;
}

/// Directions worth trying: the triangle's normals (VF), the edges' common normals and the
/// perpendicular from edge a's line to b0 (EE, for near-parallel edges), at t = 0 and t = 1.
/// The differences are taken times `square` (Prepared::square), so that the products that
/// build a direction stay finite at any magnitude (any direction is valid).
bool separated_by_a_direction(CcdPair pair, const CcdPoints& start, const CcdPoints& end, const Hull& hull,
                              const Vec3& err, Scalar delta, Scalar square) {
  for (const CcdPoints* x : {&start, &end}) {
    const CcdPoints& q = *x;
    if (pair == CcdPair::kVertexFace) {
      if (separated_along(((q[2] - q[1]) * square).cross((q[3] - q[1]) * square), hull, err, delta)) return true;
    } else {
      const Vec3 da = (q[1] - q[0]) * square, db = (q[3] - q[2]) * square;
      if (separated_along(da.cross(db), hull, err, delta)) return true;
      const Scalar aa = da.squaredNorm();
      if (aa > 0) {
        const Vec3 w = (q[2] - q[0]) * square;
        if (separated_along(w - (w.dot(da) / aa) * da, hull, err, delta)) return true;
      }
    }
  }
  return false;
}

/// F(t, u, v) in the evaluation order docs/ccd.md's error bound assumes: each coordinate within
/// err of the exact value for t, u, v ∈ [0, 1] (1 - t may round; u, v are used as given).
Vec3 evaluate(const Prepared& p, Scalar t, Scalar u, Scalar v) {
  const Scalar w0 = 1 - t;
  Vec3 f;
  for (int k = 0; k < 3; ++k) {
    const Scalar g0 = (p.a[0][k] + u * p.b[0][k]) + v * p.c[0][k];
    const Scalar g1 = (p.a[1][k] + u * p.b[1][k]) + v * p.c[1][k];
    f[k] = w0 * g0 + t * g1;
  }
  return f;
}

/// The right-hand side of a certified line test: (1 - t) s0 + t s1 > line_limit(s0, s1,
/// threshold), evaluated as written, proves (1 - t) s0 + t s1 > threshold for the exact values
/// of the doubles given (t ∈ [0, 1]). The evaluation errs by at most 3.01 u (|s0| + |s1|) (1 - t,
/// two products and a sum, each rounded once) plus underflow; 4 u and round_up cover it. It
/// does not depend on t: the advancement computes it once per line and step.
Scalar line_limit(Scalar s0, Scalar s1, Scalar threshold) {
  return round_up(threshold + 4 * kU * (std::abs(s0) + std::abs(s1)));
}

/// Result of conservative advancement: no contact before `t` (certified); `kSeparated`: none at
/// all; `kWitness`: a point of the domain at `t` is within the tolerance's reach.
struct Advance {
  enum State : std::uint8_t { kOpen, kSeparated, kWitness };
  State state = kOpen;
  Scalar t = 0;
  std::int64_t steps = 0;
};

/// Conservative advancement along directions (docs/ccd.md). At time t the difference points
/// d_i(t) = (1 - t) d_i⁰ + t d_i¹ span a hull that holds F(t, ·, ·), so for any n,
/// n·F(t, u, v) ≥ min_i n·d_i(t), and each n·d_i(t) is linear in t. With s_i^τ the computed
/// projections of the hull points and `threshold` ≥ δ‖n‖ + their error (separated_along's
/// bound), every line certified above the threshold at t_k and at t_{k+1} keeps ‖F‖ > δ on
/// [t_k, t_{k+1}]. n is the closest-point direction at t_k, for which the bound is tight; its
/// own rounding does not matter (any n is valid). Stops after `max_steps` steps, or when a step
/// gains less than 2^-30 or cannot be certified.
/// Flattened: the closest-point kernels are inlined into the loop (their unused outputs, such
/// as the squared distance, are then not computed; the values used are the same bits).
CRUMPLE_CCD_FLATTEN Advance advance(CcdPair pair, const CcdPoints& start, const CcdPoints& end,
                                         const Prepared& p, const Hull& hull, Scalar reach2,
                                         std::int64_t max_steps, Scalar max_time) {
  Advance r;
  const int half = hull.count / 2;  // the points at t = 0, then the same at t = 1
  Scalar t = 0, progress = 1;
  for (std::int64_t step = 0;; ++step) {
    if (t >= max_time) {  // no contact before t ≥ max_time
      r.state = Advance::kSeparated;
      break;
    }
    // Closest points at t in plain floating point: they only choose n and a witness candidate.
    CcdPoints x;
    for (int i = 0; i < 4; ++i) x[i] = start[i] + t * (end[i] - start[i]);
    Vec3 n;
    Scalar u, v;
    if (pair == CcdPair::kVertexFace) {
      const PointTriangleResult q = point_triangle(x[0], x[1], x[2], x[3]);
      n = x[0] - q.closest;
      u = q.barycentric[1];
      v = q.barycentric[2];
    } else {
      const SegmentSegmentResult q = segment_segment(x[0], x[1], x[2], x[3]);
      n = q.closest0 - q.closest1;
      u = q.s;
      v = q.t;
    }
    // A witness as the bisection's: a point of the domain (u, v on the 2^-40 grid, so that the
    // VF test u + v ≤ 1 is exact) whose computed F is within reach.
    // At t = 0 the witness is taken only if no step can be certified: a pair apart at t = 0 by
    // more than δ and the rounding band gets a TOI > 0 even when it is within reach.
    u = std::floor(std::clamp(u, Scalar(0), Scalar(1)) * 0x1p40) * 0x1p-40;  // NaN compares false: kept
    v = std::floor(std::clamp(v, Scalar(0), Scalar(1)) * 0x1p40) * 0x1p-40;
    bool witness = false;
    if (u >= 0 && u <= 1 && v >= 0 && v <= 1) {
      if (p.face && u + v > 1) v = 1 - u;
      witness = (evaluate(p, t, u, v) * p.square).squaredNorm() <= reach2;
    }
    const auto stop = [&] {
      if (witness) r.state = Advance::kWitness;
    };
    if (witness && step > 0) {
      stop();
      break;
    }
    if (step == max_steps || progress < 0x1p-30) {
      stop();
      break;
    }
    const Scalar len = n.norm();
    if (!(len > 0) || !std::isfinite(len)) {
      stop();
      break;
    }
    n /= len;
    std::array<Scalar, 4> s0{}, s1{};
    Scalar mag = 0;
    for (int i = 0; i < half; ++i) {
      for (int tau = 0; tau < 2; ++tau) {
        const Vec3& d = hull.points[i + tau * half];
        const Scalar a = d.x() * n.x(), b = d.y() * n.y(), c = d.z() * n.z();
        (tau == 0 ? s0 : s1)[i] = (a + b) + c;
        mag = std::max(mag, std::abs(a) + std::abs(b) + std::abs(c));
      }
    }
    // separated_along's bound: computed projections within Σ|n_k| err_k + γ3 mag of the exact.
    const Scalar nn = n.x() * n.x() + n.y() * n.y() + n.z() * n.z();
    const Scalar slack = std::abs(n.x()) * p.err.x() + std::abs(n.y()) * p.err.y() + std::abs(n.z()) * p.err.z();
    const Scalar threshold = (p.delta * std::sqrt(nn) + slack + 4 * kU * mag) * (1 + 16 * kU) + kUnderflowSlack;
    std::array<Scalar, 4> limit{};
    for (int i = 0; i < half; ++i) limit[i] = line_limit(s0[i], s1[i], threshold);
    const auto above_at = [&](Scalar time) {
      for (int i = 0; i < half; ++i) {
        if (!((1 - time) * s0[i] + time * s1[i] > limit[i])) return false;
      }
      return true;
    };
    if (!above_at(t)) {
      stop();
      break;
    }
    // Earliest time a line falls to the threshold plus a margin; verified below.
    Scalar next = 1;
    for (int i = 0; i < half; ++i) {
      if (!(s1[i] < s0[i])) continue;
      const Scalar margin = threshold + 16 * kU * (std::abs(s0[i]) + std::abs(s1[i])) + kUnderflowSlack;
      next = std::min(next, (s0[i] - margin) / (s0[i] - s1[i]));
    }
    next = std::clamp(next, t, Scalar(1));
    bool verified = false;
    for (int attempt = 0; attempt < 3 && next > t; ++attempt) {
      if ((verified = above_at(next))) break;
      next = t + (next - t) / 2;
    }
    ++r.steps;
    if (!verified) {
      stop();
      break;
    }
    progress = next - t;
    t = next;
    if (t == 1) {
      r.state = Advance::kSeparated;
      break;
    }
  }
  r.t = t;
  return r;
}

/// det[a; b; c] of three vectors whose entries are each one rounded difference of inputs,
/// evaluated in the order of Shewchuk's orient3d, with his a-priori bound
/// |fl(det) - det| ≤ (7 u + 56 u²) · permanent; we use 8 u · permanent.
struct Det {
  Scalar value;
  Scalar error;
};

Det det3(const Vec3& a, const Vec3& b, const Vec3& c) {
  const Scalar bxcy = b.x() * c.y(), cxby = c.x() * b.y();
  const Scalar cxay = c.x() * a.y(), axcy = a.x() * c.y();
  const Scalar axby = a.x() * b.y(), bxay = b.x() * a.y();
  const Scalar value = a.z() * (bxcy - cxby) + b.z() * (cxay - axcy) + c.z() * (axby - bxay);
  const Scalar permanent = (std::abs(bxcy) + std::abs(cxby)) * std::abs(a.z()) +
                           (std::abs(cxay) + std::abs(axcy)) * std::abs(b.z()) +
                           (std::abs(axby) + std::abs(bxay)) * std::abs(c.z());
  return {value, 8 * kU * permanent};
}

/// Certified sign (+1, -1, or 0 for "unknown") of a sum of determinants: the sum's rounding
/// adds at most γ_2 Σ|d_i| ≤ 3 u Σ|d_i| to the determinants' own bounds.
int certified_sign(const Det* d, int n) {
  Scalar sum = 0, abs_sum = 0, error = 0;
  for (int i = 0; i < n; ++i) {
    sum += d[i].value;
    abs_sum += std::abs(d[i].value);
    error += d[i].error;
  }
  const Scalar bound = (error + 3 * kU * abs_sum) * (1 + 8 * kU) + kUnderflowSlack;
  if (sum > bound) return 1;
  if (sum < -bound) return -1;
  return 0;
}

/// Filter 2 (δ = 0 only): contact needs the 4 points coplanar at some t. The coplanarity
/// function det[x1 - x0, x2 - x0, x3 - x0](t) is a cubic whose Bernstein coefficients on [0, 1]
/// are, up to positive factors, the sums of the mixed determinants taking j columns at t = 1
/// (j = 0..3). Same certified strict sign for all four: never coplanar.
bool never_coplanar(const CcdPoints& start, const CcdPoints& end) {
  std::array<std::array<Vec3, 3>, 2> col;
  for (int i = 0; i < 3; ++i) {
    col[0][i] = start[i + 1] - start[0];
    col[1][i] = end[i + 1] - end[0];
  }
  const auto mixed = [&](int t0, int t1, int t2) { return det3(col[t0][0], col[t1][1], col[t2][2]); };
  const Det b0[1] = {mixed(0, 0, 0)};
  const Det b1[3] = {mixed(1, 0, 0), mixed(0, 1, 0), mixed(0, 0, 1)};
  const Det b2[3] = {mixed(0, 1, 1), mixed(1, 0, 1), mixed(1, 1, 0)};
  const Det b3[1] = {mixed(1, 1, 1)};
  const int s = certified_sign(b0, 1);
  if (s == 0) return false;
  return certified_sign(b1, 3) == s && certified_sign(b2, 3) == s && certified_sign(b3, 1) == s;
}

// never_coplanar on four queries at once, one per lane of GCC's vector extension (one AVX2
// register, or two SSE2 halves in the portable kernel). Every operation is the scalar code's,
// in its order, on IEEE doubles with contraction off: each lane computes bit for bit what
// never_coplanar computes for its query.
using Lanes = Scalar __attribute__((vector_size(32)));
using LaneMask = long long __attribute__((vector_size(32)));

#define CRUMPLE_CCD_LANES inline __attribute__((always_inline))

CRUMPLE_CCD_LANES Lanes splat(Scalar x) { return Lanes{x, x, x, x}; }

/// The one range test of both lane paths (the filters' `load_lanes`, the advancement's
/// `set_up_lanes`), lane by lane on an input coordinate's magnitude |x|: clears the lanes of
/// `in_range` where |x| > 2^300 (kMaxSignFilterMagnitude) or x is not finite (NaN compares
/// false, ∞ exceeds the bound). A lane runs its query only while all 24 coordinates pass; any
/// other query is left to the scalar path, whose own range test (`in_range`) makes a non-finite
/// input a conservative hit. So a non-finite coordinate can never make a pair be marked apart.
/// (By reference and target-neutral: it inlines into the AVX2 functions too.)
CRUMPLE_CCD_LANES void keep_in_range(LaneMask& in_range, const Lanes& magnitude) {
  in_range &= magnitude <= Lanes{kMaxSignFilterMagnitude, kMaxSignFilterMagnitude, kMaxSignFilterMagnitude,
                                 kMaxSignFilterMagnitude};
}
CRUMPLE_CCD_LANES Lanes abs(Lanes x) {
  const LaneMask sign = reinterpret_cast<LaneMask>(splat(-0.0));
  return reinterpret_cast<Lanes>(reinterpret_cast<LaneMask>(x) & ~sign);
}

struct DetLanes {
  Lanes value, error;
};

CRUMPLE_CCD_LANES DetLanes det3(const Lanes (&a)[3], const Lanes (&b)[3], const Lanes (&c)[3]) {
  const Lanes bxcy = b[0] * c[1], cxby = c[0] * b[1];
  const Lanes cxay = c[0] * a[1], axcy = a[0] * c[1];
  const Lanes axby = a[0] * b[1], bxay = b[0] * a[1];
  const Lanes value = a[2] * (bxcy - cxby) + b[2] * (cxay - axcy) + c[2] * (axby - bxay);
  const Lanes permanent = (abs(bxcy) + abs(cxby)) * abs(a[2]) + (abs(cxay) + abs(axcy)) * abs(b[2]) +
                          (abs(axby) + abs(bxay)) * abs(c[2]);
  return {value, splat(8 * kU) * permanent};
}

/// certified_sign, lane by lane: `pos` where it is +1, `neg` where it is -1.
CRUMPLE_CCD_LANES void certified_sign(const DetLanes* d, int n, LaneMask& pos, LaneMask& neg) {
  Lanes sum = splat(0), abs_sum = splat(0), error = splat(0);
  for (int i = 0; i < n; ++i) {
    sum += d[i].value;
    abs_sum += abs(d[i].value);
    error += d[i].error;
  }
  const Lanes bound = (error + splat(3 * kU) * abs_sum) * splat(1 + 8 * kU) + splat(kUnderflowSlack);
  pos = sum > bound;
  neg = sum < -bound;
}

/// The points of queries q[index[0..3]] (lanes past `count` repeat the first), x[τ][point][axis],
/// per axis their largest |coordinate| (max_abs_coordinates), and the lanes whose every
/// coordinate passes `keep_in_range`.
struct QueryLanes {
  Lanes x[2][4][3];
  Lanes m[3];
  LaneMask in_range;
};

CRUMPLE_CCD_LANES void load_lanes(const detail::CcdQuery* q, const std::uint8_t* index, std::size_t count,
                                  QueryLanes& out) {
  const detail::CcdQuery* l[4];
  for (std::size_t i = 0; i < 4; ++i) l[i] = &q[index[i < count ? i : 0]];
  for (std::size_t i = 0; i < 4; ++i) {
    for (int k = 0; k < 3; ++k) {
      out.x[0][i][k] = Lanes{l[0]->start[i][k], l[1]->start[i][k], l[2]->start[i][k], l[3]->start[i][k]};
      out.x[1][i][k] = Lanes{l[0]->end[i][k], l[1]->end[i][k], l[2]->end[i][k], l[3]->end[i][k]};
    }
  }
  out.in_range = ~LaneMask{};
  for (int k = 0; k < 3; ++k) {
    Lanes m = splat(0);  // the lanes out of range may drop a NaN here: their m is not used
    for (int tau = 0; tau < 2; ++tau) {
      for (int i = 0; i < 4; ++i) {
        const Lanes a = abs(out.x[tau][i][k]);
        m = m > a ? m : a;
        keep_in_range(out.in_range, a);
      }
    }
    out.m[k] = m;
  }
}

/// Lanes whose query `ccd` computes unscaled, with every filter: every coordinate in range
/// (`keep_in_range`), the largest |coordinate| ≥ 2^-300 (0, where no filter rejects, is left
/// out too).
CRUMPLE_CCD_LANES LaneMask unscaled_lanes(const QueryLanes& q) {
  Lanes m = q.m[0] > q.m[1] ? q.m[0] : q.m[1];
  m = m > q.m[2] ? m : q.m[2];
  return q.in_range & (m >= splat(kMinUnscaledMagnitude));
}

CRUMPLE_CCD_LANES unsigned lane_bits(LaneMask yes, std::size_t count) {
  unsigned bits = 0;
  for (std::size_t l = 0; l < count; ++l) bits |= (yes[l] != 0 ? 1u : 0u) << l;
  return bits;
}

/// Bit l set: query l of `q` (l < count; the other lanes repeat query 0) has its largest
/// |coordinate| in [2^-300, 2^300] and never_coplanar would return true for it.
CRUMPLE_CCD_LANES unsigned never_coplanar_lanes(const QueryLanes& q, std::size_t count) {
  Lanes col[2][3][3];
  for (int tau = 0; tau < 2; ++tau) {
    for (int i = 0; i < 3; ++i) {
      for (int k = 0; k < 3; ++k) col[tau][i][k] = q.x[tau][i + 1][k] - q.x[tau][0][k];
    }
  }
  const auto mixed = [&](int t0, int t1, int t2) { return det3(col[t0][0], col[t1][1], col[t2][2]); };
  const DetLanes b0[1] = {mixed(0, 0, 0)};
  const DetLanes b1[3] = {mixed(1, 0, 0), mixed(0, 1, 0), mixed(0, 0, 1)};
  const DetLanes b2[3] = {mixed(0, 1, 1), mixed(1, 0, 1), mixed(1, 1, 0)};
  const DetLanes b3[1] = {mixed(1, 1, 1)};
  LaneMask pos[4], neg[4];
  certified_sign(b0, 1, pos[0], neg[0]);
  certified_sign(b1, 3, pos[1], neg[1]);
  certified_sign(b2, 3, pos[2], neg[2]);
  certified_sign(b3, 1, pos[3], neg[3]);
  const LaneMask apart = (pos[0] & pos[1] & pos[2] & pos[3]) | (neg[0] & neg[1] & neg[2] & neg[3]);
  return lane_bits(apart & unscaled_lanes(q), count);
}

/// separated_along(n, hull, err, delta) lane by lane, the hull's `count` points in `d`.
CRUMPLE_CCD_LANES LaneMask separated_along_lanes(const Lanes (&n)[3], const Lanes (*d)[3], int count,
                                                 const Lanes (&err)[3], Lanes delta) {
  const Lanes nn = n[0] * n[0] + n[1] * n[1] + n[2] * n[2];
  const LaneMask usable = (nn > splat(0)) & (nn <= splat(std::numeric_limits<Scalar>::max()));  // > 0, finite
  Lanes lo = splat(INFINITY), hi = splat(-INFINITY), mag = splat(0);
  for (int i = 0; i < count; ++i) {
    const Lanes x = d[i][0] * n[0], y = d[i][1] * n[1], z = d[i][2] * n[2];
    const Lanes s = (x + y) + z;
    lo = s < lo ? s : lo;  // std::min(lo, s)
    hi = hi < s ? s : hi;  // std::max(hi, s)
    const Lanes a = abs(x) + abs(y) + abs(z);
    mag = mag < a ? a : mag;
  }
  const Lanes slack = abs(n[0]) * err[0] + abs(n[1]) * err[1] + abs(n[2]) * err[2];
  Lanes root = nn;
  for (int l = 0; l < 4; ++l) root[l] = std::sqrt(nn[l]);
  const Lanes bound = (delta * root + slack + splat(4 * kU) * mag) * splat(1 + 16 * kU) + splat(kUnderflowSlack);
  return usable & ((lo > bound) | (hi < -bound));
}

CRUMPLE_CCD_LANES void cross(const Lanes (&a)[3], const Lanes (&b)[3], Lanes (&out)[3]) {
  out[0] = a[1] * b[2] - a[2] * b[1];  // Eigen's cross, in its order
  out[1] = a[2] * b[0] - a[0] * b[2];
  out[2] = a[0] * b[1] - a[1] * b[0];
}

/// Bit l set: query l is computed unscaled by `ccd` and separated_by_a_direction (after
/// hull_may_touch built its hull and set_bounds its err) would return true for it.
CRUMPLE_CCD_LANES unsigned separated_by_a_direction_lanes(CcdPair pair, const QueryLanes& q, Scalar delta,
                                                          std::size_t count) {
  const auto& x = q.x;
  Lanes err[3];
  for (int k = 0; k < 3; ++k) err[k] = splat(kCornerErrorFactor) * q.m[k] + splat(kUnderflowSlack);
  Lanes hull[8][3];
  int points = 0;
  for (int tau = 0; tau < 2; ++tau) {
    const auto add = [&](int i, int j) {
      for (int k = 0; k < 3; ++k) hull[points][k] = x[tau][i][k] - x[tau][j][k];
      ++points;
    };
    if (pair == CcdPair::kVertexFace) {
      add(0, 1);
      add(0, 2);
      add(0, 3);
    } else {
      add(0, 2);
      add(0, 3);
      add(1, 2);
      add(1, 3);
    }
  }
  const Lanes d = splat(delta);
  LaneMask apart = LaneMask{0, 0, 0, 0};
  for (int tau = 0; tau < 2; ++tau) {
    const auto diff = [&](int i, int j, Lanes (&out)[3]) {
      for (int k = 0; k < 3; ++k) out[k] = x[tau][i][k] - x[tau][j][k];  // (times square = 1)
    };
    Lanes n[3];
    if (pair == CcdPair::kVertexFace) {
      Lanes e1[3], e2[3];
      diff(2, 1, e1);
      diff(3, 1, e2);
      cross(e1, e2, n);
      apart |= separated_along_lanes(n, hull, points, err, d);
    } else {
      Lanes da[3], db[3], w[3];
      diff(1, 0, da);
      diff(3, 2, db);
      cross(da, db, n);
      apart |= separated_along_lanes(n, hull, points, err, d);
      const Lanes aa = da[0] * da[0] + da[1] * da[1] + da[2] * da[2];
      diff(2, 0, w);
      const Lanes c = (w[0] * da[0] + w[1] * da[1] + w[2] * da[2]) / aa;
      for (int k = 0; k < 3; ++k) n[k] = w[k] - c * da[k];
      apart |= (aa > splat(0)) & separated_along_lanes(n, hull, points, err, d);
    }
  }
  return lane_bits(apart & unscaled_lanes(q), count);
}

/// The two filters over `index[0..count)` of `queries`, four at a time: bit set in out[i] =
/// 1 (never coplanar, for `coplanarity`) or 2 (a separating direction, for `pair`).
CRUMPLE_CCD_LANES void filter_batch(std::span<const detail::CcdQuery> queries, const std::uint8_t* index,
                                    std::size_t count, bool coplanarity, CcdPair pair, Scalar delta,
                                    std::uint8_t* out) {
  for (std::size_t i = 0; i < count; i += 4) {
    const std::size_t n = std::min<std::size_t>(4, count - i);
    QueryLanes q;
    load_lanes(queries.data(), index + i, n, q);
    const unsigned bits = coplanarity ? never_coplanar_lanes(q, n) : separated_by_a_direction_lanes(pair, q, delta, n);
    for (std::size_t l = 0; l < n; ++l) out[i + l] = static_cast<std::uint8_t>(bits >> l & 1u);
  }
}

void filter_portable(std::span<const detail::CcdQuery> queries, const std::uint8_t* index, std::size_t count,
                     bool coplanarity, CcdPair pair, Scalar delta, std::uint8_t* out) {
  filter_batch(queries, index, count, coplanarity, pair, delta, out);
}

__attribute__((target("avx2"))) void filter_avx2(std::span<const detail::CcdQuery> queries,
                                                 const std::uint8_t* index, std::size_t count, bool coplanarity,
                                                 CcdPair pair, Scalar delta, std::uint8_t* out) {
  filter_batch(queries, index, count, coplanarity, pair, delta, out);
}

#undef CRUMPLE_CCD_LANES

struct Box {
  Scalar t0, t1, u0, u1, v0, v1;
  int depth;
};

/// Earliest t first; among equal t, the deeper box first (depth-first towards a hit).
struct LaterFirst {
  bool operator()(const Box& x, const Box& y) const {
    return x.t0 > y.t0 || (x.t0 == y.t0 && x.depth < y.depth);
  }
};

/// Bisection of [t_begin, 1] × [0, 1]² (no contact before t_begin is already certified); stops
/// without a hit once the earliest live box starts at or after max_time. Never inlined: few
/// queries reach it (none on most real frame pairs), and the flattened callers would each copy it.
__attribute__((noinline)) CcdResult bisect(const Prepared& p, Scalar reach2, Scalar tol_t, std::int64_t max_boxes, Scalar t_begin,
                 Scalar max_time) {
  std::vector<Box> storage;
  storage.reserve(64);
  std::priority_queue<Box, std::vector<Box>, LaterFirst> queue(LaterFirst{}, std::move(storage));
  queue.push({t_begin, 1, 0, 1, 0, 1, 0});
  CcdResult result;
  while (!queue.empty()) {
    const Box box = queue.top();
    queue.pop();
    if (box.t0 >= max_time) break;  // every live box starts at or after max_time
    if (result.boxes >= max_boxes) {
      // The popped box has the smallest t0 of every box not yet ruled out.
      result.hit = true;
      result.toi = box.t0;
      result.outcome = CcdOutcome::kHitBudget;
      return result;
    }
    ++result.boxes;
    // Corner values: index bit 2 = t, bit 1 = u, bit 0 = v.
    std::array<Vec3, 8> f;
    const Scalar us[2] = {box.u0, box.u1};
    const Scalar vs[2] = {box.v0, box.v1};
    const Scalar ts[2] = {box.t0, box.t1};
    for (int iu = 0; iu < 2; ++iu) {
      for (int iv = 0; iv < 2; ++iv) {
        Vec3 g[2];
        for (int tau = 0; tau < 2; ++tau) {
          for (int k = 0; k < 3; ++k) {
            g[tau][k] = (p.a[tau][k] + us[iu] * p.b[tau][k]) + vs[iv] * p.c[tau][k];
          }
        }
        for (int it = 0; it < 2; ++it) {
          const Scalar w1 = ts[it];
          const Scalar w0 = 1 - w1;  // may round (docs/ccd.md's bound allows it)
          for (int k = 0; k < 3; ++k) f[it * 4 + iu * 2 + iv][k] = w0 * g[0][k] + w1 * g[1][k];
        }
      }
    }
    Vec3 lo = f[0], hi = f[0];
    for (int i = 1; i < 8; ++i) {
      lo = lo.cwiseMin(f[i]);
      hi = hi.cwiseMax(f[i]);
    }
    bool rejected = false;
    for (int k = 0; k < 3; ++k) {
      if (lo[k] > p.bound[k] || hi[k] < -p.bound[k]) rejected = true;
    }
    if (!rejected && p.delta > 0) {
      // Euclidean distance from 0 to the box [lo - err, hi + err] (each gap rounded at most
      // 2 u high, the sum of squares 8 u) above δ: no point of the box within δ.
      Scalar sum = 0;
      for (int k = 0; k < 3; ++k) {
        const Scalar gap = std::max({lo[k] - p.err[k], -hi[k] - p.err[k], Scalar(0)}) * p.square;
        sum += gap * gap;
      }
      rejected = sum * (1 - 16 * kU) > p.delta2_up;
    }
    if (rejected) continue;
    // Witness corners: inside the domain and at computed Euclidean distance ≤ reach =
    // δ (1 + σ) + ε + ‖err‖, i.e. a point of the box truly within δ (1 + σ) + ε + 2‖err‖. Earliest witness
    // time: 0 (t0), 1 (t1), 2 (none).
    int witness = 2;
    for (int i = 0; i < 8 && witness > 0; ++i) {
      if (p.face && us[(i >> 1) & 1] + vs[i & 1] > 1) continue;  // exact sum
      if ((f[i] * p.square).squaredNorm() <= reach2) witness = std::min(witness, i >> 2);
    }
    const bool t_small = box.t1 - box.t0 <= tol_t;
    if (witness == 0 || (witness == 1 && t_small)) {
      result.hit = true;
      result.toi = box.t0;
      result.outcome = CcdOutcome::kHitTolerance;
      return result;
    }
    int axis = -1;
    if (witness == 1) {
      axis = 0;  // a near-contact by t1: only the time tolerance is missing (tol_t ≥ kMinWidth)
    } else {
      // Width of the corner values along each parameter; split the widest splittable one.
      Scalar w[3] = {0, 0, 0};  // t, u, v
      for (int i = 0; i < 8; ++i) {
        for (int bit = 0; bit < 3; ++bit) {
          const int mask = 4 >> bit;
          if (i & mask) continue;
          w[bit] = std::max(w[bit], (f[i | mask] - f[i]).cwiseAbs().maxCoeff());
        }
      }
      const Scalar widths[3] = {box.t1 - box.t0, box.u1 - box.u0, box.v1 - box.v0};
      Scalar best = -1;
      for (int d = 0; d < 3; ++d) {
        if (widths[d] > kMinWidth && w[d] > best) {
          best = w[d];
          axis = d;
        }
      }
    }
    if (axis < 0) {
      result.hit = true;
      result.toi = box.t0;
      result.outcome = CcdOutcome::kHitPrecision;
      return result;
    }
    Box lo_half = box, hi_half = box;
    lo_half.depth = hi_half.depth = box.depth + 1;
    if (axis == 0) {
      const Scalar mid = (box.t0 + box.t1) / 2;
      lo_half.t1 = hi_half.t0 = mid;
    } else if (axis == 1) {
      const Scalar mid = (box.u0 + box.u1) / 2;
      lo_half.u1 = hi_half.u0 = mid;
    } else {
      const Scalar mid = (box.v0 + box.v1) / 2;
      lo_half.v1 = hi_half.v0 = mid;
    }
    for (const Box& child : {lo_half, hi_half}) {
      // VF: (u, v) must meet the triangle u, v ≥ 0, u + v ≤ 1 (the sum is exact).
      if (p.face && child.u0 + child.v0 > 1) continue;
      queue.push(child);
    }
  }
  result.hit = false;
  result.outcome = CcdOutcome::kSeparatedBisection;
  return result;
}

}  // namespace

std::string_view to_string(CcdOutcome outcome) {
  switch (outcome) {
    case CcdOutcome::kSeparatedHull: return "separated-hull";
    case CcdOutcome::kSeparatedCoplanarity: return "separated-coplanarity";
    case CcdOutcome::kSeparatedDirection: return "separated-direction";
    case CcdOutcome::kSeparatedBisection: return "separated-bisection";
    case CcdOutcome::kSeparatedAdvancement: return "separated-advancement";
    case CcdOutcome::kHitTolerance: return "hit-tolerance";
    case CcdOutcome::kHitPrecision: return "hit-precision";
    case CcdOutcome::kHitBudget: return "hit-budget";
    case CcdOutcome::kHitOutOfRange: return "hit-out-of-range";
  }
  return "unknown";
}

Scalar ccd_hull_bound(Scalar magnitude, Scalar delta) {
  if (!(magnitude <= kMaxMagnitude)) return INFINITY;  // NaN too
  return round_up(axis_error(magnitude) + delta);
}

Vec3 ccd_rounding_bound(const CcdPoints& start, const CcdPoints& end) {
  const Vec3 m = max_abs_coordinates(start, end);
  Vec3 err;
  for (int k = 0; k < 3; ++k) err[k] = axis_error(m[k]);
  return err;
}

namespace {

/// Filters of an unscaled query known not to reject (their batched versions in ccd_detail.hpp
/// gave 0), and so skipped.
constexpr unsigned kCoplanarityDone = 1, kDirectionDone = 2;

/// `ccd` after its option checks, skipping the filters in `done` for an unscaled query.
/// Never inlined: the advancement lanes call it only for scaled or out-of-range queries.
__attribute__((noinline)) CcdResult ccd_checked(CcdPair pair, const CcdPoints& start, const CcdPoints& end,
                                                const CcdOptions& options, unsigned done);

void check_options(const CcdOptions& options) {
  const Scalar delta = options.min_separation;
  CRUMPLE_CHECK(delta >= 0 && delta <= kMaxMagnitude, "ccd: min_separation must be in [0, 2^1000]");
  CRUMPLE_CHECK(options.max_boxes >= 1, "ccd: max_boxes must be >= 1");
  CRUMPLE_CHECK(options.max_advance_steps >= 0, "ccd: max_advance_steps must be >= 0");
  CRUMPLE_CHECK(options.max_time >= 0 && options.max_time <= 1, "ccd: max_time must be in [0, 1]");
  CRUMPLE_CHECK(options.distance_tolerance >= 0 && options.time_tolerance >= 0 && options.separation_tolerance >= 0,
                "ccd: tolerances must be >= 0");
}

/// What the search of a query (advancement, bisection) needs, from ccd_filters.
struct Setup {
  Prepared p;
  Hull hull;
  Scalar reach2 = 0, tol_t = 0;
  /// Whether the advancement runs: magnitude ≤ 2^300 (the closest-point kernels square
  /// lengths) and max_advance_steps > 0.
  bool advance = false;
};

/// The witnesses' reach, squared, of lengths times `square` (Prepared::square), from the
/// query's err, its hull's `extent` and the options: a computed ‖F‖ ≤ reach puts the exact point
/// within reach + ‖err‖. One function for the scalar set-up and the advancement's lanes.
Scalar reach_squared(const Vec3& err, Scalar square, Scalar extent, const CcdOptions& options) {
  const Scalar eps = std::max(options.distance_tolerance * extent, 4 * err.maxCoeff());
  const Scalar reach = options.min_separation * (1 + options.separation_tolerance) + eps + (err * square).norm() / square;
  return (reach * square) * (reach * square);
}

/// ccd_checked after its scaling (`m`: the query's largest |coordinate| per axis): the range
/// check, the filters not in `done`, and what the search needs, in `s`. True when `result` is
/// the answer.
bool ccd_filters(CcdPair pair, const CcdPoints& start, const CcdPoints& end, const CcdOptions& options,
                 unsigned done, const Vec3& m, CcdResult& result, Setup& s) {
  const Scalar delta = options.min_separation;
  s.hull.count = 0;  // `s` may be reused: what the code below does not always set
  s.p.square = 1;
  if (!in_range(start, end)) {
    result.hit = true;
    result.toi = 0;
    result.outcome = CcdOutcome::kHitOutOfRange;
    return true;
  }
  Prepared& p = s.p;
  set_bounds(p, m, delta);
  Scalar extent = 0;
  Hull& hull = s.hull;
  if (!hull_may_touch(pair, start, end, p.bound, extent, hull)) {
    result.outcome = CcdOutcome::kSeparatedHull;
    return true;
  }
  prepare(p, pair, start, end);
  const Scalar magnitude = m.maxCoeff();
  if (delta == 0 && magnitude <= kMaxSignFilterMagnitude && (done & kCoplanarityDone) == 0 &&
      never_coplanar(start, end)) {
    result.outcome = CcdOutcome::kSeparatedCoplanarity;
    return true;
  }
  if ((done & kDirectionDone) == 0 && separated_by_a_direction(pair, start, end, hull, p.err, delta, p.square)) {
    result.outcome = CcdOutcome::kSeparatedDirection;
    return true;
  }
  s.reach2 = reach_squared(p.err, p.square, extent, options);
  s.tol_t = std::clamp(options.time_tolerance, kMinWidth, Scalar(1));
  s.advance = magnitude <= kMaxSignFilterMagnitude && options.max_advance_steps > 0;
  return false;
}

/// The result when the advancement `a` answers the query (separated, or a witness at a.t).
bool advance_answers(const Advance& a, CcdResult& result) {
  result.advance_steps = a.steps;
  if (a.state == Advance::kSeparated) {
    result.outcome = CcdOutcome::kSeparatedAdvancement;
    return true;
  }
  if (a.state == Advance::kWitness) {
    result.hit = true;
    result.toi = a.t;
    result.outcome = CcdOutcome::kHitTolerance;
    return true;
  }
  return false;
}

/// The result of a query whose filters left it open, from the advancement's `a` (an open
/// advancement at t = 0 with no step where `s.advance` is false) and, when `a` leaves the
/// question open, the bisection of [a.t, 1].
CcdResult ccd_search(const Setup& s, const Advance& a, const CcdOptions& options) {
  CcdResult result;
  if (advance_answers(a, result)) return result;
  result = bisect(s.p, s.reach2, s.tol_t, options.max_boxes, a.t, options.max_time);
  result.advance_steps = a.steps;
  return result;
}

// Flattened, as `advance`: the filters, the advancement and the bisection inlined (the same
// operations, the same bits).
CRUMPLE_CCD_FLATTEN CcdResult ccd_checked(CcdPair pair, const CcdPoints& start, const CcdPoints& end,
                                               const CcdOptions& options, unsigned done) {
  const Scalar delta = options.min_separation;
  CcdResult result;
  const Vec3 m = max_abs_coordinates(start, end);
  // The batched filters vouch only for queries in [2^-300, 2^300] (unscaled_lanes): any other
  // query, scaled or not, runs every filter.
  if (!(m.maxCoeff() >= kMinUnscaledMagnitude && m.maxCoeff() <= kMaxSignFilterMagnitude)) done = 0;
  if (const Scalar largest = m.maxCoeff();
      largest <= kMaxMagnitude && (largest > kMaxUnscaledMagnitude || (largest > 0 && largest < kMinUnscaledMagnitude))) {
    // The same query scaled by 2^k into [1, 2), when no coordinate loses a bit: the underflow
    // slack of the error bounds, 2^-1000, no longer dominates tiny coordinates (at 1e-300 it made
    // err a tenth of the query's extent: hits everywhere near contact), and the filters and the
    // advancement, which need cubes below overflow, run on huge ones (up to the range, 2^1000;
    // beyond, and for NaN, the conservative hit below). δ is rounded up.
    const int k = -std::ilogb(largest);
    CcdPoints s = start, e = end;
    bool exact = true;
    for (int i = 0; i < 4; ++i) {
      for (int a = 0; a < 3; ++a) {
        s[i][a] = std::scalbn(s[i][a], k);
        e[i][a] = std::scalbn(e[i][a], k);
        exact = exact && std::scalbn(s[i][a], -k) == start[i][a] && std::scalbn(e[i][a], -k) == end[i][a];
      }
    }
    if (exact) {
      CcdOptions scaled = options;
      Scalar d = std::scalbn(delta, k);
      if (std::scalbn(d, -k) < delta) d = std::nextafter(d, INFINITY);
      // A δ beyond 2^1000 at magnitude 1 keeps every pair within it, as the unscaled δ does.
      scaled.min_separation = std::min(d, kMaxMagnitude);
      // ccd_never_coplanar gives 0 for every scaled query: the filter runs on the scaled one.
      return ccd_checked(pair, s, e, scaled, 0);
    }
  }
  Setup setup;
  if (ccd_filters(pair, start, end, options, done, m, result, setup)) return result;
  Advance a;
  if (setup.advance) {
    // The closest-point kernels need squared lengths that do not overflow; they only choose
    // directions and witness candidates, so any finite result is safe.
    a = advance(pair, start, end, setup.p, setup.hull, setup.reach2, options.max_advance_steps, options.max_time);
  }
  return ccd_search(setup, a, options);
}

// The advancement of four queries in lockstep, one per lane (AVX2 only: the closest points come
// from segment_segment_x4 / point_triangle_x4). Every lane performs `advance`'s operations in its
// order on IEEE doubles with contraction off, and those kernels give segment_segment's and
// point_triangle's bits, so each lane computes bit for bit the sequence of steps that `advance`
// computes for its query, and stops where it stops. The lanes apply only to queries that `ccd`
// computes unscaled (largest |coordinate| in [2^-300, 2^300]), where Prepared::square is 1 and
// the multiplications by it (exact) are left out.
#define CRUMPLE_ADVANCE_LANES inline __attribute__((always_inline, target("avx2")))

// splat and abs for the AVX2 functions below (clang refuses to pass a 32-byte vector between a
// function compiled for AVX2 and one that is not, even inlined): the same operations.
CRUMPLE_ADVANCE_LANES Lanes lane_splat(Scalar x) { return Lanes{x, x, x, x}; }
CRUMPLE_ADVANCE_LANES Lanes lane_abs(Lanes x) {
  const LaneMask sign = reinterpret_cast<LaneMask>(lane_splat(-0.0));
  return reinterpret_cast<Lanes>(reinterpret_cast<LaneMask>(x) & ~sign);
}

/// One query per lane: its points, what `advance` reads, and its loop's state.
struct AdvanceLanes {
  Lanes x0[4][3], x1[4][3];  // the points at t = 0 and t = 1, stored by `load_lane`
  Lanes dx[4][3];            // end − start; this and the rest set by `set_up_lanes`
  Lanes hull[8][3];          // Hull::points: `half` at t = 0, then the same at t = 1
  Lanes a[2][3], b[2][3], c[2][3];  // Prepared's differences
  Lanes err[3], delta, reach2;
  Lanes t, progress, step;  // the loop's t, progress and step (= steps taken; exact in a double)
};

/// Lane l takes the points of query (start, end): the only values stored one lane at a time.
void load_lane(AdvanceLanes& lanes, int l, const CcdPoints& start, const CcdPoints& end) {
  for (int i = 0; i < 4; ++i) {
    for (int k = 0; k < 3; ++k) {
      lanes.x0[i][k][l] = start[i][k];
      lanes.x1[i][k][l] = end[i][k];
    }
  }
}

/// Lane `to` takes the points of lane `from` (a lane with no query keeps running on a copy of
/// a live one: finite inputs in range, results not read).
void copy_points(AdvanceLanes& lanes, int from, int to) {
  for (int i = 0; i < 4; ++i) {
    for (int k = 0; k < 3; ++k) {
      lanes.x0[i][k][to] = lanes.x0[i][k][from];
      lanes.x1[i][k][to] = lanes.x1[i][k][from];
    }
  }
}

CRUMPLE_ADVANCE_LANES Lanes floor(Lanes x) {
  return reinterpret_cast<Lanes>(_mm256_floor_pd(reinterpret_cast<__m256d>(x)));
}
CRUMPLE_ADVANCE_LANES Lanes sqrt(Lanes x) {
  return reinterpret_cast<Lanes>(_mm256_sqrt_pd(reinterpret_cast<__m256d>(x)));
}
CRUMPLE_ADVANCE_LANES unsigned mask_bits(LaneMask m) {
  return static_cast<unsigned>(_mm256_movemask_pd(reinterpret_cast<__m256d>(m)));
}
CRUMPLE_ADVANCE_LANES Lanes load(const std::array<Scalar, 4>& x) {
  return reinterpret_cast<Lanes>(_mm256_loadu_pd(x.data()));
}
CRUMPLE_ADVANCE_LANES void store(std::array<Scalar, 4>& to, Lanes x) {
  _mm256_storeu_pd(to.data(), reinterpret_cast<__m256d>(x));
}

/// std::clamp(x, 0, 1) (NaN stays NaN, and fails the witness' range test), floored to the
/// 2^-40 grid.
CRUMPLE_ADVANCE_LANES Lanes snap(Lanes x) {
  x = x < lane_splat(0) ? lane_splat(0) : (lane_splat(1) < x ? lane_splat(1) : x);
  return floor(x * lane_splat(0x1p40)) * lane_splat(0x1p-40);
}

/// `advance`'s above_at: every line (1 − time) s0 + time s1 certified above its limit.
template <int Half>
CRUMPLE_ADVANCE_LANES LaneMask above_at(Lanes time, const Lanes (&s0)[Half], const Lanes (&s1)[Half],
                                        const Lanes (&limit)[Half]) {
  LaneMask all = ~LaneMask{};
  for (int i = 0; i < Half; ++i) all &= (lane_splat(1) - time) * s0[i] + time * s1[i] > limit[i];
  return all;
}

/// What `set_up_lanes` finds, bit l for lane l.
struct LaneSetup {
  unsigned unscaled = 0;  ///< every coordinate in range (`keep_in_range`), the largest ≥ 2^-300
  unsigned apart = 0;     ///< the hull filter rejects
  Lanes extent;           ///< the hull points' largest |coordinate|
};

/// ccd_filters' set-up of every lane's query from its points (x0, x1), four at once: the
/// largest |coordinate| per axis (max_abs_coordinates), err and the hull bound (set_bounds),
/// the hull points, its test and extent (hull_may_touch), the differences (prepare) and
/// end − start (`advance`'s motion), each by the scalar code's operations (maxima and minima of
/// finite values do not depend on their order). For the lanes in `unscaled`, ccd_filters runs
/// these unscaled (Prepared::square = 1) and in_range holds, so their values are its bits; the
/// other lanes' values are not used.
template <bool Face>
CRUMPLE_ADVANCE_LANES LaneSetup set_up_lanes(AdvanceLanes& L, Scalar delta) {
  constexpr int half = Face ? 3 : 4;
  const Lanes zero = lane_splat(0);
  LaneMask in_range = ~LaneMask{};
  Lanes m[3], largest = zero;
  for (int k = 0; k < 3; ++k) {
    m[k] = zero;
    for (int i = 0; i < 4; ++i) {
      L.dx[i][k] = L.x1[i][k] - L.x0[i][k];
      const Lanes a0 = lane_abs(L.x0[i][k]), a1 = lane_abs(L.x1[i][k]);
      keep_in_range(in_range, a0);
      keep_in_range(in_range, a1);
      m[k] = m[k] < a0 ? a0 : m[k];
      m[k] = m[k] < a1 ? a1 : m[k];
    }
    largest = largest < m[k] ? m[k] : largest;
    L.err[k] = lane_splat(kCornerErrorFactor) * m[k] + lane_splat(kUnderflowSlack);  // axis_error
  }
  L.delta = lane_splat(delta);
  Lanes lo[3], hi[3];
  for (int k = 0; k < 3; ++k) {
    lo[k] = lane_splat(INFINITY);
    hi[k] = lane_splat(-INFINITY);
  }
  for (int tau = 0; tau < 2; ++tau) {
    const Lanes (&x)[4][3] = tau == 0 ? L.x0 : L.x1;
    constexpr int kFirst[2][4] = {{0, 0, 1, 1}, {2, 3, 2, 3}};  // EE: a_i − b_j
    for (int j = 0; j < half; ++j) {
      const int p = Face ? 0 : kFirst[0][j], q = Face ? j + 1 : kFirst[1][j];
      Lanes (&d)[3] = L.hull[j + tau * half];
      for (int k = 0; k < 3; ++k) {
        d[k] = x[p][k] - x[q][k];
        lo[k] = d[k] < lo[k] ? d[k] : lo[k];
        hi[k] = hi[k] < d[k] ? d[k] : hi[k];
      }
    }
    for (int k = 0; k < 3; ++k) {  // prepare
      if constexpr (Face) {
        L.a[tau][k] = x[0][k] - x[1][k];
        L.b[tau][k] = x[1][k] - x[2][k];
        L.c[tau][k] = x[1][k] - x[3][k];
      } else {
        L.a[tau][k] = x[0][k] - x[2][k];
        L.b[tau][k] = x[1][k] - x[0][k];
        L.c[tau][k] = x[2][k] - x[3][k];
      }
    }
  }
  LaneMask apart = LaneMask{};
  Lanes extent = zero;
  for (int k = 0; k < 3; ++k) {
    const Lanes bound = (L.err[k] + L.delta) * lane_splat(1 + 0x1p-50) + lane_splat(kUnderflowSlack);  // round_up
    apart |= (lo[k] > bound) | (hi[k] < -bound);
    const Lanes l = lane_abs(lo[k]), h = lane_abs(hi[k]);
    extent = extent < l ? l : extent;
    extent = extent < h ? h : extent;
  }
  LaneSetup out;
  out.unscaled = mask_bits(in_range & (largest >= lane_splat(kMinUnscaledMagnitude)));
  out.apart = mask_bits(apart);
  out.extent = extent;
  return out;
}

/// Lanes whose advancement stopped in a step, and how.
struct Stopped {
  unsigned stop = 0, separated = 0, witness = 0;
};

/// One iteration of `advance`'s loop on every lane (`Face`: VF, else EE). Lanes that stop keep
/// the t at which `advance` returns; the others move to the next step.
template <bool Face>
CRUMPLE_ADVANCE_LANES Stopped advance_step(AdvanceLanes& L, FourPointBatch& batch, Scalar max_time, Scalar max_steps) {
  constexpr int half = Face ? 3 : 4;
  const Lanes zero = lane_splat(0), one = lane_splat(1);
  const Lanes t = L.t;
  LaneMask stop = t >= lane_splat(max_time);  // no contact before t ≥ max_time
  LaneMask separated = stop;
  // Closest points at t (the query's points at t, as `advance` computes them).
  for (int i = 0; i < 4; ++i) {
    for (int k = 0; k < 3; ++k) store(batch.coords[static_cast<std::size_t>(3 * i + k)], L.x0[i][k] + t * L.dx[i][k]);
  }
  Lanes n[3], u, v, len;
  if constexpr (Face) {
    const PointTriangleBatchResult q = point_triangle_x4(batch);
    u = load(q.barycentric[1]);
    v = load(q.barycentric[2]);
    len = load(q.away_norm);
    for (int k = 0; k < 3; ++k) n[k] = load(q.normal[static_cast<std::size_t>(k)]);  // n / len
  } else {
    const SegmentBatchResult q = segment_segment_x4(batch);
    u = load(q.s);
    v = load(q.t);
    len = load(q.gap_norm);  // closest1 − closest0 = −n, of the same norm
    for (int k = 0; k < 3; ++k) n[k] = -load(q.normal[static_cast<std::size_t>(k)]);  // (−x) / y = −(x / y)
  }
  // The witness candidate on the 2^-40 grid.
  u = snap(u);
  v = snap(v);
  const LaneMask inside = (u >= zero) & (u <= one) & (v >= zero) & (v <= one);
  if constexpr (Face) v = (inside & (u + v > one)) ? one - u : v;
  const Lanes w0 = one - t;
  Lanes f[3];
  for (int k = 0; k < 3; ++k) {
    const Lanes g0 = (L.a[0][k] + u * L.b[0][k]) + v * L.c[0][k];
    const Lanes g1 = (L.a[1][k] + u * L.b[1][k]) + v * L.c[1][k];
    f[k] = w0 * g0 + t * g1;
  }
  const LaneMask witness = inside & ((f[0] * f[0] + f[1] * f[1]) + f[2] * f[2] <= L.reach2);
  stop |= witness & (L.step > zero);
  stop |= (L.step == lane_splat(max_steps)) | (L.progress < lane_splat(0x1p-30));
  stop |= ~((len > zero) & (len <= lane_splat(std::numeric_limits<Scalar>::max())));  // > 0 and finite
  // The projections of the hull points on n and the certified threshold.
  Lanes s0[half], s1[half];
  Lanes mag = zero;
  for (int i = 0; i < half; ++i) {
    for (int tau = 0; tau < 2; ++tau) {
      const Lanes (&d)[3] = L.hull[i + tau * half];
      const Lanes x = d[0] * n[0], y = d[1] * n[1], z = d[2] * n[2];
      (tau == 0 ? s0 : s1)[i] = (x + y) + z;
      const Lanes m = lane_abs(x) + lane_abs(y) + lane_abs(z);
      mag = mag < m ? m : mag;  // std::max(mag, m)
    }
  }
  const Lanes nn = n[0] * n[0] + n[1] * n[1] + n[2] * n[2];
  const Lanes slack = lane_abs(n[0]) * L.err[0] + lane_abs(n[1]) * L.err[1] + lane_abs(n[2]) * L.err[2];
  const Lanes threshold =
      (L.delta * sqrt(nn) + slack + lane_splat(4 * kU) * mag) * lane_splat(1 + 16 * kU) + lane_splat(kUnderflowSlack);
  Lanes limit[half];
  for (int i = 0; i < half; ++i) {
    limit[i] = (threshold + lane_splat(4 * kU) * (lane_abs(s0[i]) + lane_abs(s1[i]))) * lane_splat(1 + 0x1p-50) + lane_splat(kUnderflowSlack);
  }
  stop |= ~above_at<half>(t, s0, s1, limit);
  // The earliest time a line falls to the threshold plus a margin, then its verification.
  Lanes next = one;
  for (int i = 0; i < half; ++i) {
    const Lanes margin = threshold + lane_splat(16 * kU) * (lane_abs(s0[i]) + lane_abs(s1[i])) + lane_splat(kUnderflowSlack);
    const Lanes candidate = (s0[i] - margin) / (s0[i] - s1[i]);
    next = ((s1[i] < s0[i]) & (candidate < next)) ? candidate : next;  // std::min(next, candidate)
  }
  next = next < t ? t : (one < next ? one : next);  // std::clamp(next, t, 1)
  const LaneMask go = ~stop;
  LaneMask verified = LaneMask{};
  LaneMask trying = go & (next > t);
  for (int attempt = 0; attempt < 3 && mask_bits(trying) != 0; ++attempt) {
    const LaneMask ok = above_at<half>(next, s0, s1, limit);
    verified |= trying & ok;
    const LaneMask failed = trying & ~ok;
    next = failed ? t + (next - t) / lane_splat(2) : next;
    trying = failed & (next > t);
  }
  L.step = go ? L.step + one : L.step;  // ++r.steps
  stop |= go & ~verified;
  const LaneMask moved = go & verified;
  L.progress = moved ? next - t : L.progress;
  L.t = moved ? next : t;
  const LaneMask reached_one = moved & (L.t == one);
  stop |= reached_one;
  separated |= reached_one;
  return {mask_bits(stop), mask_bits(separated), mask_bits(witness)};
}

/// ccd_after_direction on each query of `queries` (all of type `Face`), the advancement in lanes.
/// A query's points are stored in a lane once; its set-up (ccd_filters' values) is computed in
/// lanes before the step that follows a refill. A query the lanes do not compute unscaled runs
/// ccd_checked; one the hull filter rejects is answered here; an advancement that ends open
/// gets its scalar set-up again for the bisection (rare).
template <bool Face>
__attribute__((target("avx2"))) CRUMPLE_CCD_FLATTEN void after_direction_lanes(std::span<const detail::CcdQuery> queries,
                                                           const CcdOptions& options, CcdResult* out) {
  constexpr CcdPair pair = Face ? CcdPair::kVertexFace : CcdPair::kEdgeEdge;
  constexpr unsigned done = kCoplanarityDone | kDirectionDone;
  AdvanceLanes lanes{};  // zeroed once: a VF query leaves hull rows 6 and 7 unset
  std::array<std::size_t, 4> who{};
  std::size_t next_query = 0;
  // Lane l takes the next query's points.
  const auto refill = [&](int l) {
    if (next_query == queries.size()) return false;
    const std::size_t i = next_query++;
    load_lane(lanes, l, queries[i].start, queries[i].end);
    who[static_cast<std::size_t>(l)] = i;
    return true;
  };
  unsigned live = 0;   // lanes advancing a query
  unsigned fresh = 0;  // lanes holding a query not yet set up
  for (int l = 0; l < 4; ++l) fresh |= (refill(l) ? 1u : 0u) << l;
  const Scalar max_steps = static_cast<Scalar>(options.max_advance_steps);
  FourPointBatch batch;  // filled at every step (not value-initialised there)
  unsigned foreign = 0xFu & ~fresh;  // lanes holding no query, or one outside the lanes' range
  for (;;) {
    while (fresh != 0) {
      const LaneSetup set = set_up_lanes<Face>(lanes, options.min_separation);
      unsigned again = 0;
      for (unsigned f = fresh; f != 0; f &= f - 1) {
        const int l = __builtin_ctz(f);
        const std::size_t i = who[static_cast<std::size_t>(l)];
        const unsigned bit = 1u << l;
        foreign &= ~bit;
        if ((set.unscaled & bit) == 0) {
          out[i] = ccd_checked(pair, queries[i].start, queries[i].end, options, done);  // scaled, or out of range
          foreign |= bit;
        } else if ((set.apart & bit) != 0) {
          out[i] = CcdResult{};
          out[i].outcome = CcdOutcome::kSeparatedHull;
        } else {
          const Vec3 err(lanes.err[0][l], lanes.err[1][l], lanes.err[2][l]);
          lanes.reach2[l] = reach_squared(err, 1, set.extent[l], options);
          lanes.t[l] = 0;
          lanes.progress[l] = 1;
          lanes.step[l] = 0;
          live |= bit;
          continue;
        }
        if (refill(l)) again |= bit;
      }
      fresh = again;
    }
    if (live == 0) return;
    if (foreign != 0) {
      // A lane with no query keeps running on a copy of a live one (finite inputs in range,
      // results not read).
      const int first = __builtin_ctz(live);
      for (unsigned f = foreign; f != 0; f &= f - 1) copy_points(lanes, first, __builtin_ctz(f));
      foreign = 0;
      set_up_lanes<Face>(lanes, options.min_separation);  // the live lanes' values are unchanged
    }
    const Stopped s = advance_step<Face>(lanes, batch, options.max_time, max_steps);
    for (unsigned ended = s.stop & live; ended != 0; ended &= ended - 1) {
      const int l = __builtin_ctz(ended);
      const std::size_t i = who[static_cast<std::size_t>(l)];
      Advance a;
      a.state = (s.separated >> l & 1u) ? Advance::kSeparated : (s.witness >> l & 1u) ? Advance::kWitness : Advance::kOpen;
      a.t = lanes.t[l];
      a.steps = static_cast<std::int64_t>(lanes.step[l]);
      CcdResult r;
      if (!advance_answers(a, r)) {
        const detail::CcdQuery& q = queries[i];
        Setup setup;
        CcdResult decided;
        ccd_filters(pair, q.start, q.end, options, done, max_abs_coordinates(q.start, q.end), decided, setup);
        r = ccd_search(setup, a, options);
      }
      out[i] = r;
      live &= ~(1u << l);
      if (refill(l)) fresh |= 1u << l;
    }
  }
}

#undef CRUMPLE_ADVANCE_LANES

}  // namespace

CcdResult ccd(CcdPair pair, const CcdPoints& start, const CcdPoints& end, const CcdOptions& options) {
  check_options(options);
  // Most queries end at the hull filter: decided first in vector registers (the same answer).
  if (detail::ccd_has_avx2() && hull_apart_avx2(pair, start, end, options.min_separation)) return CcdResult{};
  return ccd_checked(pair, start, end, options, 0);
}

void ccd(CcdPair pair, std::span<const CcdQuery> queries, const CcdOptions& options, std::span<CcdResult> out) {
  check_options(options);
  CRUMPLE_CHECK(out.size() == queries.size(), "ccd: one result per query");
  const bool lanes = detail::ccd_has_avx2();
  if (!lanes) {
    for (std::size_t i = 0; i < queries.size(); ++i) out[i] = ccd_checked(pair, queries[i].start, queries[i].end, options, 0);
    return;
  }
  // Blocks of at most 256 queries (the filters take one-byte indices). Each stage answers the
  // queries its filter rejects, with the outcome `ccd` gives them, and passes the others on:
  // the hull (hull_apart_avx2: exactly hull_may_touch's rejections), at δ = 0 the coplanarity
  // signs, the separating directions (both vouch only for unscaled queries, on which the hull
  // test before them is exactly `ccd`'s), then ccd_after_direction's advancement in lanes.
  constexpr std::size_t kBlock = 256;
  const Scalar delta = options.min_separation;
  std::array<std::uint8_t, kBlock> open{}, verdict{};
  std::vector<CcdQuery> kept(std::min(kBlock, queries.size()));
  std::vector<CcdResult> kept_out(kept.size());
  for (std::size_t base = 0; base < queries.size(); base += kBlock) {
    const std::span<const CcdQuery> block = queries.subspan(base, std::min(kBlock, queries.size() - base));
    std::size_t count = 0;
    std::size_t i = 0;
    for (; i + 4 <= block.size(); i += 4) {
      const unsigned apart = hull_apart_x4(pair, &block[i], delta);
      for (std::size_t l = 0; l < 4; ++l) {
        if ((apart >> l & 1u) != 0) {
          out[base + i + l] = CcdResult{};  // kSeparatedHull
        } else {
          open[count++] = static_cast<std::uint8_t>(i + l);
        }
      }
    }
    for (; i < block.size(); ++i) {
      if (hull_apart_avx2(pair, block[i].start, block[i].end, delta)) {
        out[base + i] = CcdResult{};
      } else {
        open[count++] = static_cast<std::uint8_t>(i);
      }
    }
    for (const bool coplanarity : {true, false}) {
      if (count == 0 || (coplanarity && delta != 0)) continue;
      filter_avx2(block, open.data(), count, coplanarity, pair, delta, verdict.data());
      CcdResult apart;
      apart.outcome = coplanarity ? CcdOutcome::kSeparatedCoplanarity : CcdOutcome::kSeparatedDirection;
      std::size_t left = 0;
      for (std::size_t j = 0; j < count; ++j) {
        if (verdict[j] != 0) {
          out[base + open[j]] = apart;
        } else {
          open[left++] = open[j];
        }
      }
      count = left;
    }
    for (std::size_t j = 0; j < count; ++j) kept[j] = block[open[j]];
    detail::ccd_after_direction(pair, std::span<const CcdQuery>(kept.data(), count), options, kept_out.data(), true);
    for (std::size_t j = 0; j < count; ++j) out[base + open[j]] = kept_out[j];
  }
}

namespace detail {

bool ccd_has_avx2() { return has_avx2(); }

namespace {

void run_filter(std::span<const CcdQuery> queries, const std::uint8_t* index, std::size_t count, bool coplanarity,
                CcdPair pair, Scalar delta, std::uint8_t* out, bool avx2) {
  if (avx2 && ccd_has_avx2()) {
    filter_avx2(queries, index, count, coplanarity, pair, delta, out);
  } else {
    filter_portable(queries, index, count, coplanarity, pair, delta, out);
  }
}

}  // namespace

void ccd_never_coplanar(std::span<const CcdQuery> queries, std::uint8_t* out, bool avx2) {
  // One filter call per 256 queries (the index is one byte).
  static constexpr std::array<std::uint8_t, 256> index = [] {
    std::array<std::uint8_t, 256> first{};
    for (std::size_t i = 0; i < first.size(); ++i) first[i] = static_cast<std::uint8_t>(i);
    return first;
  }();
  for (std::size_t i = 0; i < queries.size(); i += index.size()) {
    const std::size_t n = std::min(index.size(), queries.size() - i);
    run_filter(queries.subspan(i), index.data(), n, true, CcdPair::kVertexFace, 0, out + i, avx2);
  }
}

void ccd_separated_by_a_direction(CcdPair pair, std::span<const CcdQuery> queries,
                                  std::span<const std::uint8_t> index, Scalar delta, std::uint8_t* out, bool avx2) {
  run_filter(queries, index.data(), index.size(), false, pair, delta, out, avx2);
}

CcdResult ccd_scalar(CcdPair pair, const CcdPoints& start, const CcdPoints& end, const CcdOptions& options) {
  check_options(options);
  return ccd_checked(pair, start, end, options, 0);
}

CcdResult ccd_after_coplanarity(CcdPair pair, const CcdPoints& start, const CcdPoints& end,
                                const CcdOptions& options) {
  check_options(options);
  return ccd_checked(pair, start, end, options, kCoplanarityDone);
}

CcdResult ccd_after_direction(CcdPair pair, const CcdPoints& start, const CcdPoints& end, const CcdOptions& options) {
  check_options(options);
  return ccd_checked(pair, start, end, options, kCoplanarityDone | kDirectionDone);
}

void ccd_after_direction(CcdPair pair, std::span<const CcdQuery> queries, const CcdOptions& options, CcdResult* out,
                         bool lanes) {
  check_options(options);
  // The lanes count steps in doubles: exact far beyond any budget that can be spent.
  // Without steps (max_advance_steps = 0) every query goes to the bisection: one at a time.
  if (lanes && ccd_has_avx2() && options.max_advance_steps > 0 && options.max_advance_steps <= (std::int64_t{1} << 40)) {
    if (pair == CcdPair::kVertexFace) {
      after_direction_lanes<true>(queries, options, out);
    } else {
      after_direction_lanes<false>(queries, options, out);
    }
    return;
  }
  for (std::size_t i = 0; i < queries.size(); ++i) {
    out[i] = ccd_checked(pair, queries[i].start, queries[i].end, options, kCoplanarityDone | kDirectionDone);
  }
}

}  // namespace detail

CcdResult vertex_face_ccd(const CcdPoints& start, const CcdPoints& end, const CcdOptions& options) {
  return ccd(CcdPair::kVertexFace, start, end, options);
}

CcdResult edge_edge_ccd(const CcdPoints& start, const CcdPoints& end, const CcdOptions& options) {
  return ccd(CcdPair::kEdgeEdge, start, end, options);
}

}  // namespace crumple::geometry
