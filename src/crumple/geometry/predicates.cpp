/// \file
/// Exact stage of the orientation predicates: floating-point expansion arithmetic.
///
/// An expansion is a sum x_0 + x_1 + ... + x_{n-1} of doubles, sorted by increasing
/// magnitude and non-overlapping, so that its sign is the sign of its last (largest)
/// non-zero component. Error-free transformations (Knuth's two-sum, Dekker's or FMA
/// two-product) and Shewchuk's zero-eliminating expansion sum and scaling (Shewchuk 1997,
/// §2.5-2.6, Theorems 13 and 19) keep every intermediate exact. Everything lives in
/// fixed-size stack arrays: no heap, no exceptions.

#include <crumple/geometry/predicates.hpp>

#include <array>
#include <cmath>
#include <cstddef>

namespace crumple::geometry::detail {
namespace {

/// x + y == a + b exactly, x = fl(a + b) (Knuth's branch-free two-sum).
inline void two_sum(double a, double b, double& x, double& y) {
  x = a + b;
  const double b_virtual = x - a;
  const double a_virtual = x - b_virtual;
  y = (a - a_virtual) + (b - b_virtual);
}

/// x + y == a - b exactly, x = fl(a - b).
inline void two_diff(double a, double b, double& x, double& y) {
  x = a - b;
  const double b_virtual = a - x;
  const double a_virtual = x + b_virtual;
  y = (a - a_virtual) + (b_virtual - b);
}

/// x + y == a + b exactly, valid only when |a| >= |b| (or a == 0): Dekker's fast two-sum.
inline void fast_two_sum(double a, double b, double& x, double& y) {
  x = a + b;
  y = b - (x - a);
}

/// x + y == a * b exactly, x = fl(a * b).
inline void two_product(double a, double b, double& x, double& y) {
  x = a * b;
#if defined(FP_FAST_FMA)
  y = std::fma(a, b, -x);
#else
  // Dekker/Veltkamp: split each factor into two 26-bit halves whose products are exact.
  constexpr double kSplitter = 134217729.0;  // 2^27 + 1
  const double ca = kSplitter * a;
  const double a_hi = ca - (ca - a);
  const double a_lo = a - a_hi;
  const double cb = kSplitter * b;
  const double b_hi = cb - (cb - b);
  const double b_lo = b - b_hi;
  const double err1 = x - a_hi * b_hi;
  const double err2 = err1 - a_lo * b_hi;
  const double err3 = err2 - a_hi * b_lo;
  y = a_lo * b_lo - err3;
#endif
}

/// A fixed-capacity expansion. `n` components are valid, increasing magnitude, non-zero.
template <std::size_t N>
struct Expansion {
  std::array<double, N> c;  // only the first n are meaningful
  std::size_t n = 0;

  int sign() const { return n == 0 ? 0 : (c[n - 1] > 0 ? 1 : -1); }
};

/// Exact e + f (Shewchuk's fast expansion sum with zero elimination): the components of both
/// are taken in order of increasing magnitude (merged on the fly) and swept with two-sums.
/// Needs round-to-nearest-even and non-overlapping, zero-free inputs.
template <std::size_t M, std::size_t N>
Expansion<M + N> sum(const Expansion<M>& e, const Expansion<N>& f) {
  Expansion<M + N> out;
  std::size_t i = 0, j = 0;
  const auto next = [&]() -> double {
    if (j >= f.n || (i < e.n && std::abs(e.c[i]) < std::abs(f.c[j]))) return e.c[i++];
    return f.c[j++];
  };
  const std::size_t total = e.n + f.n;
  if (total == 0) return out;
  double q = next();
  if (total >= 2) {
    double h;
    const double second = next();
    fast_two_sum(second, q, q, h);  // |second| >= |first|
    if (h != 0) out.c[out.n++] = h;
    for (std::size_t m = 2; m < total; ++m) {
      const double g = next();
      two_sum(q, g, q, h);
      if (h != 0) out.c[out.n++] = h;
    }
  }
  if (q != 0) out.c[out.n++] = q;
  return out;
}

template <std::size_t N>
Expansion<N> negate(Expansion<N> e) {
  for (std::size_t i = 0; i < e.n; ++i) e.c[i] = -e.c[i];
  return e;
}

/// Exact a * b as an expansion of at most 2 components.
Expansion<2> product(double a, double b) {
  double x, y;
  two_product(a, b, x, y);
  Expansion<2> out;
  if (y != 0) out.c[out.n++] = y;
  if (x != 0) out.c[out.n++] = x;
  return out;
}

/// Exact a*b - c*d (at most 4 components).
Expansion<4> product_difference(double a, double b, double c, double d) {
  return sum(product(a, b), negate(product(c, d)));
}

/// Exact b * e (Shewchuk's scale-expansion with zero elimination).
template <std::size_t N>
Expansion<2 * N> scale(const Expansion<N>& e, double b) {
  Expansion<2 * N> out;
  if (e.n == 0 || b == 0) return out;
  double q, h;
  two_product(e.c[0], b, q, h);
  if (h != 0) out.c[out.n++] = h;
  for (std::size_t i = 1; i < e.n; ++i) {
    double p_hi, p_lo;
    two_product(e.c[i], b, p_hi, p_lo);
    double sum_hi;
    two_sum(q, p_lo, sum_hi, h);
    if (h != 0) out.c[out.n++] = h;
    fast_two_sum(p_hi, sum_hi, q, h);
    if (h != 0) out.c[out.n++] = h;
  }
  if (q != 0) out.c[out.n++] = q;
  return out;
}

/// Exact det[[px,py,pz],[qx,qy,qz],[rx,ry,rz]] from the xy-minors
/// m_qr = qx ry - rx qy etc.: det = pz m_qr - qz m_pr + rz m_pq (24 components at most).
Expansion<24> det3(double pz, double qz, double rz, const Expansion<4>& m_qr,
                   const Expansion<4>& m_pr, const Expansion<4>& m_pq) {
  return sum(sum(scale(m_qr, pz), scale(m_pr, -qz)), scale(m_pq, rz));
}

}  // namespace

int orient3d_exact(const Vec3& a, const Vec3& b, const Vec3& c, const Vec3& d) {
  // A repeated point makes the determinant exactly zero (common: mesh neighbours share
  // corners), and needs no arithmetic.
  if (a == b || a == c || a == d || b == c || b == d || c == d) return 0;

  // Stage 1: when the nine differences b-a, c-a, d-a are exact in double (always true for
  // nearby points, by Sterbenz's lemma), det[u; v; w] is expanded from them directly:
  // 3 x (2x2 minor: 4 components, scaled: 8) -> at most 24 components.
  std::array<double, 9> diff, tail;
  const Vec3* const others[3] = {&b, &c, &d};
  bool exact_differences = true;
  for (int r = 0; r < 3; ++r) {
    for (int k = 0; k < 3; ++k) {
      two_diff((*others[r])[k], a[k], diff[3 * r + k], tail[3 * r + k]);
      exact_differences = exact_differences && tail[3 * r + k] == 0;
    }
  }
  if (exact_differences) {
    const double ux = diff[0], uy = diff[1], uz = diff[2];
    const double vx = diff[3], vy = diff[4], vz = diff[5];
    const double wx = diff[6], wy = diff[7], wz = diff[8];
    // det = ux (vy wz - vz wy) + uy (vz wx - vx wz) + uz (vx wy - vy wx)
    const Expansion<8> t1 = scale(product_difference(vy, wz, vz, wy), ux);
    const Expansion<8> t2 = scale(product_difference(vz, wx, vx, wz), uy);
    const Expansion<8> t3 = scale(product_difference(vx, wy, vy, wx), uz);
    return sum(sum(t1, t2), t3).sign();
  }

  // Stage 2 (general): det[b-a; c-a; d-a] = -det4 where det4 is the 4x4 determinant with
  // rows (p, 1) for p = a, b, c, d. Expanding det4 along the column of ones:
  //   det4 = D(a,b,c) - D(a,b,d) + D(a,c,d) - D(b,c,d),  D = 3x3 determinant of coordinates.
  // Working on the original coordinates avoids the rounding of the differences.
  const Expansion<4> m_ab = product_difference(a.x(), b.y(), b.x(), a.y());
  const Expansion<4> m_ac = product_difference(a.x(), c.y(), c.x(), a.y());
  const Expansion<4> m_ad = product_difference(a.x(), d.y(), d.x(), a.y());
  const Expansion<4> m_bc = product_difference(b.x(), c.y(), c.x(), b.y());
  const Expansion<4> m_bd = product_difference(b.x(), d.y(), d.x(), b.y());
  const Expansion<4> m_cd = product_difference(c.x(), d.y(), d.x(), c.y());
  const Expansion<24> abc = det3(a.z(), b.z(), c.z(), m_bc, m_ac, m_ab);
  const Expansion<24> abd = det3(a.z(), b.z(), d.z(), m_bd, m_ad, m_ab);
  const Expansion<24> acd = det3(a.z(), c.z(), d.z(), m_cd, m_ad, m_ac);
  const Expansion<24> bcd = det3(b.z(), c.z(), d.z(), m_cd, m_bd, m_bc);
  // -det4 = (D(a,b,d) - D(a,b,c)) + (D(b,c,d) - D(a,c,d))
  const Expansion<96> result = sum(sum(abd, negate(abc)), sum(bcd, negate(acd)));
  return result.sign();
}

int orient2d_exact(Scalar ax, Scalar ay, Scalar bx, Scalar by, Scalar cx, Scalar cy) {
  if ((ax == bx && ay == by) || (ax == cx && ay == cy) || (bx == cx && by == cy)) return 0;
  double acx, acx_t, bcx, bcx_t, acy, acy_t, bcy, bcy_t;
  two_diff(ax, cx, acx, acx_t);
  two_diff(bx, cx, bcx, bcx_t);
  two_diff(ay, cy, acy, acy_t);
  two_diff(by, cy, bcy, bcy_t);
  if (acx_t == 0 && bcx_t == 0 && acy_t == 0 && bcy_t == 0) {
    // Exact differences: (a-c) x (b-c) as one product difference.
    return product_difference(acx, bcy, acy, bcx).sign();
  }
  // (a-c) x (b-c) = m_ab - m_ac + m_bc with m_pq = px qy - qx py (the cx*cy terms cancel).
  const Expansion<4> m_ab = product_difference(ax, by, bx, ay);
  const Expansion<4> m_ac = product_difference(ax, cy, cx, ay);
  const Expansion<4> m_bc = product_difference(bx, cy, cx, by);
  return sum(sum(m_ab, negate(m_ac)), m_bc).sign();
}

}  // namespace crumple::geometry::detail
