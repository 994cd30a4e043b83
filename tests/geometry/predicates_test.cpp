/// Orientation predicates against exact integer determinants (__int128), on inputs built to
/// defeat the floating-point filter: exactly coplanar/collinear integer configurations and
/// 1-unit perturbations of them at coordinates up to 2^38 (the double evaluation then loses
/// ~70 bits), scaled by powers of two and translated far from the origin (both exact).

#include <crumple/geometry/predicates.hpp>

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstdint>

#include "geometry_test_support.hpp"

namespace crumple::geometry {
namespace {

__extension__ typedef __int128 Int128;

using test::json_case;
using test::Rng;

int sign(Int128 x) { return (x > 0) - (x < 0); }

using I3 = std::array<std::int64_t, 3>;

/// Exact sign of det[b - a; c - a; d - a] for integer points with |coordinate| <= 2^39.
int orient3d_int(const I3& a, const I3& b, const I3& c, const I3& d) {
  const Int128 ux = b[0] - a[0], uy = b[1] - a[1], uz = b[2] - a[2];
  const Int128 vx = c[0] - a[0], vy = c[1] - a[1], vz = c[2] - a[2];
  const Int128 wx = d[0] - a[0], wy = d[1] - a[1], wz = d[2] - a[2];
  return sign(ux * (vy * wz - vz * wy) + uy * (vz * wx - vx * wz) + uz * (vx * wy - vy * wx));
}

/// Exact sign of (a - c) x (b - c) for integer points with |coordinate| <= 2^60.
int orient2d_int(std::int64_t ax, std::int64_t ay, std::int64_t bx, std::int64_t by,
                 std::int64_t cx, std::int64_t cy) {
  return sign(Int128(ax - cx) * Int128(by - cy) - Int128(ay - cy) * Int128(bx - cx));
}

/// Integer point -> double point, scaled by 2^scale_exp and translated by `offset` (all exact
/// as long as the results need at most 53 significant bits).
Vec3 to_vec(const I3& p, int scale_exp, double offset) {
  return Vec3(std::ldexp(double(p[0]), scale_exp) + offset, std::ldexp(double(p[1]), scale_exp) + offset,
              std::ldexp(double(p[2]), scale_exp) + offset);
}

TEST(Predicates, Orient3dMatchesExactIntegers) {
  Rng rng("Predicates.Orient3dMatchesExactIntegers", 31337);
  long failures = 0, zeros = 0;
  for (int i = 0; i < 60000; ++i) {
    // Coordinates up to 2^R; d = a + j (b - a) + k (c - a) + small perturbation.
    const int R = std::array{4, 12, 20, 30, 35}[i % 5];
    const std::int64_t lim = std::int64_t(1) << R;
    I3 a, b, c, d;
    for (int k = 0; k < 3; ++k) {
      a[k] = rng.integer64(-lim, lim);
      b[k] = rng.integer64(-lim, lim);
      c[k] = rng.integer64(-lim, lim);
    }
    const std::int64_t j = rng.integer(-3, 3), k = rng.integer(-3, 3);
    for (int m = 0; m < 3; ++m) {
      d[m] = a[m] + j * (b[m] - a[m]) + k * (c[m] - a[m]) + (i % 3 == 0 ? 0 : rng.integer(-1, 1));
    }
    if (i % 11 == 0) c = b;  // degenerate triangle
    const int want = orient3d_int(a, b, c, d);
    zeros += want == 0;
    // Scale by 2^e and translate by 2^t (exact: R + 3 + |e| bits < 53 are enough here).
    const int e = (i % 4 == 0) ? -40 : ((i % 4 == 1) ? 7 : 0);
    const double offset = (i % 2 == 0) ? 0.0 : std::ldexp(1.0, 52 - (R + 4)) * std::ldexp(1.0, e);
    const Vec3 A = to_vec(a, e, offset), B = to_vec(b, e, offset), C = to_vec(c, e, offset),
               D = to_vec(d, e, offset);
    const int got = orient3d(A, B, C, D);
    const int exact = detail::orient3d_exact(A, B, C, D);
    // Antisymmetry under a swap, invariance under an even permutation.
    const int swapped = orient3d(B, A, C, D);
    const int rotated = orient3d(B, C, A, D);
    const int other_base = orient3d(D, C, B, A);  // det[c-d; b-d; a-d] = det[b-a; c-a; d-a]
    // Three points at once (a corner of the plane among them: exactly 0).
    const std::array<int, 3> sides = orient3d_sides(A, B, C, D, A, D);
    if (got != want || exact != want || swapped != -want || rotated != want || other_base != want ||
        sides != std::array<int, 3>{want, 0, want}) {
      if (++failures <= 8) {
        ADD_FAILURE() << "orient3d: want " << want << " got " << got << " exact " << exact
                      << " swapped " << swapped << " rotated " << rotated << " other " << other_base
                      << " sides " << sides[0] << " " << sides[1] << " " << sides[2]
                      << "\n  input: " << json_case("orient3d", {A, B, C, D});
      }
    }
  }
  std::printf("[ info     ] orient3d: %ld exactly coplanar cases of 60000\n", zeros);
  EXPECT_GT(zeros, 10000);
  EXPECT_EQ(failures, 0);
}

TEST(Predicates, Orient3dFilteredEqualsExactOnFloats) {
  // Random doubles and nearly coplanar doubles (d computed in floating point on the plane):
  // the filtered result must always equal the unfiltered exact one.
  Rng rng("Predicates.Orient3dFilteredEqualsExactOnFloats", 4242);
  long failures = 0, nonzero = 0;
  for (int i = 0; i < 60000; ++i) {
    const Scalar S = rng.scale(-6, 6);
    const Vec3 o = rng.coin() ? Vec3::Zero() : rng.vec(-1e3 * S, 1e3 * S);
    const Vec3 a = o + rng.vec(-S, S), b = o + rng.vec(-S, S), c = o + rng.vec(-S, S);
    Vec3 d = o + rng.vec(-S, S);
    if (i % 4 != 0) d = a + rng.uniform(-2, 2) * (b - a) + rng.uniform(-2, 2) * (c - a);
    const int got = orient3d(a, b, c, d), exact = detail::orient3d_exact(a, b, c, d);
    const std::array<int, 3> sides = orient3d_sides(a, b, c, d, c, d);
    nonzero += exact != 0;
    if ((got != exact || sides != std::array<int, 3>{exact, 0, exact}) && ++failures <= 8) {
      ADD_FAILURE() << "filtered " << got << " exact " << exact << " sides " << sides[0] << " " << sides[1] << " "
                    << sides[2]
                    << "\n  input: " << json_case("orient3d", {a, b, c, d});
    }
  }
  EXPECT_EQ(failures, 0);
  EXPECT_GT(nonzero, 30000);
}

TEST(Predicates, Orient2dMatchesExactIntegers) {
  Rng rng("Predicates.Orient2dMatchesExactIntegers", 2718);
  long failures = 0;
  for (int i = 0; i < 60000; ++i) {
    const int R = std::array{3, 20, 40, 50}[i % 4];
    const std::int64_t lim = std::int64_t(1) << R;
    const std::int64_t ax = rng.integer64(-lim, lim), ay = rng.integer64(-lim, lim);
    const std::int64_t bx = rng.integer64(-lim, lim), by = rng.integer64(-lim, lim);
    // c on the line ab (j integer) plus a perturbation of -1, 0 or 1.
    const std::int64_t j = rng.integer(-2, 3);
    const std::int64_t cx = ax + j * (bx - ax) + rng.integer(-1, 1) * (i % 2);
    const std::int64_t cy = ay + j * (by - ay) + rng.integer(-1, 1) * (i % 2);
    if (std::abs(cx) >= (std::int64_t(1) << 53) || std::abs(cy) >= (std::int64_t(1) << 53)) continue;
    const int want = orient2d_int(ax, ay, bx, by, cx, cy);
    const int got = orient2d(double(ax), double(ay), double(bx), double(by), double(cx), double(cy));
    const int rot = orient2d(double(bx), double(by), double(cx), double(cy), double(ax), double(ay));
    const int swp = orient2d(double(bx), double(by), double(ax), double(ay), double(cx), double(cy));
    if ((got != want || rot != want || swp != -want) && ++failures <= 8) {
      ADD_FAILURE() << "orient2d want " << want << " got " << got << " rot " << rot << " swp " << swp
                    << " for (" << ax << "," << ay << ") (" << bx << "," << by << ") (" << cx << ","
                    << cy << ")";
    }
  }
  EXPECT_EQ(failures, 0);
}

TEST(Predicates, Orient2dNearlyCollinearGrid) {
  // Shewchuk's classic stress: a = (0.5 + x ulp, 0.5 + y ulp) against the line through
  // (12,12) and (24,24). Scaled by 2^53 all coordinates are integers below 2^58, so the
  // exact sign is (x - y) up to the orientation: a is on the line iff x == y.
  const double ulp = std::ldexp(1.0, -53);
  long failures = 0;
  for (int x = 0; x < 64; ++x) {
    for (int y = 0; y < 64; ++y) {
      const double ax = 0.5 + x * ulp, ay = 0.5 + y * ulp;
      const int got = orient2d(ax, ay, 12, 12, 24, 24);
      const std::int64_t s = std::int64_t(1) << 53;
      const int want = orient2d_int(s / 2 + x, s / 2 + y, 12 * s, 12 * s, 24 * s, 24 * s);
      failures += got != want;
    }
  }
  EXPECT_EQ(failures, 0);
}

TEST(Predicates, ProjectedOrientationIsTheNormalComponent) {
  Rng rng("Predicates.ProjectedOrientationIsTheNormalComponent", 99);
  for (int i = 0; i < 2000; ++i) {
    const Vec3 a = rng.vec(-1, 1), b = rng.vec(-1, 1), c = rng.vec(-1, 1);
    const Vec3 n = (b - a).cross(c - a);
    for (int k = 0; k < 3; ++k) {
      if (std::abs(n[k]) < 1e-6) continue;
      EXPECT_EQ(orient2d_projected(a, b, c, k), n[k] > 0 ? 1 : -1);
    }
    if (n.norm() > 1e-6) {
      EXPECT_EQ(orient3d(a, b, c, a + n), 1);
      EXPECT_EQ(orient3d(a, b, c, a - n), -1);
    }
  }
}

}  // namespace
}  // namespace crumple::geometry
