/// k-DOP properties for K = 6, 14, 18, 26: the axis tables, containment of the bounded points,
/// inflation as a Minkowski sum with a ball (which fails if an axis is not normalised),
/// sweeping as a Minkowski sum with a segment, merging, and conservative overlap.
///
/// Slack: projections are computed in double, so a point that was never `extend`ed can land
/// up to ~2 ulps of its coordinates outside a slab that contains it mathematically. Checks
/// on such derived points allow kSlackUlps * eps * (|p| + d); checks on the points that built
/// the k-DOP are exact.

#include <crumple/geometry/kdop.hpp>

#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <type_traits>
#include <vector>

#include "geometry_test_support.hpp"

namespace crumple::geometry {
namespace {

using test::kEps;
using test::Rng;

constexpr Scalar kSlackUlps = 8;

template <class T>
class KdopTest : public ::testing::Test {};

using Ks = ::testing::Types<std::integral_constant<int, 6>, std::integral_constant<int, 14>,
                            std::integral_constant<int, 18>, std::integral_constant<int, 26>>;
TYPED_TEST_SUITE(KdopTest, Ks);

template <int K>
bool contains_with_slack(const Kdop<K>& k, const Vec3& p, Scalar slack) {
  const auto q = Kdop<K>::project(p);
  for (int j = 0; j < Kdop<K>::kAxes; ++j) {
    if (q[j] < k.min(j) - slack || q[j] > k.max(j) + slack) return false;
  }
  return true;
}

std::vector<Vec3> random_points(Rng& rng, int n, Scalar S, const Vec3& o) {
  std::vector<Vec3> pts(n);
  for (Vec3& p : pts) p = o + rng.vec(-S, S);
  return pts;
}

TYPED_TEST(KdopTest, AxisTable) {
  constexpr int K = TypeParam::value;
  using D = Kdop<K>;
  static_assert(D::kAxes == K / 2);
  int coordinate = 0, cube_diagonal = 0, edge_diagonal = 0;
  Rng rng("KdopTest.AxisTable", 5);
  for (int j = 0; j < D::kAxes; ++j) {
    const Vec3 a = D::axis(j);
    EXPECT_NEAR(a.norm(), 1.0, 4 * kEps) << "axis " << j << " is not normalised";
    for (int i = 0; i < j; ++i) EXPECT_LT(std::abs(a.dot(D::axis(i))), 1 - 1e-6) << i << "," << j;
    const int zeros = (a.array() == 0).count();
    coordinate += zeros == 2;
    cube_diagonal += zeros == 0;
    edge_diagonal += zeros == 1;
    // The projection code agrees with the table.
    for (int t = 0; t < 100; ++t) {
      const Vec3 p = rng.vec(-10, 10);
      EXPECT_NEAR(D::project(p)[j], a.dot(p), 8 * kEps * 10);
    }
  }
  EXPECT_EQ(coordinate, 3);
  EXPECT_TRUE(D::axis(0) == Vec3::UnitX() && D::axis(1) == Vec3::UnitY() && D::axis(2) == Vec3::UnitZ());
  EXPECT_EQ(cube_diagonal, (K == 14 || K == 26) ? 4 : 0);
  EXPECT_EQ(edge_diagonal, (K == 18 || K == 26) ? 6 : 0);
}

TYPED_TEST(KdopTest, EmptyIsTheIdentity) {
  constexpr int K = TypeParam::value;
  using D = Kdop<K>;
  D e;
  EXPECT_TRUE(e.empty());
  EXPECT_FALSE(e.contains(Vec3::Zero()));
  EXPECT_FALSE(e.overlaps(e));
  EXPECT_TRUE(D::from_points({}).empty());
  const D k = D::from_triangle(Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0));
  EXPECT_FALSE(k.overlaps(e));
  EXPECT_FALSE(e.overlaps(k));
  EXPECT_TRUE(k.contains(e));
  D m = k;
  m.merge(e);
  for (int j = 0; j < D::kAxes; ++j) EXPECT_TRUE(m.min(j) == k.min(j) && m.max(j) == k.max(j));
  e.inflate(1.0);
  e.sweep(Vec3(1, 2, 3));
  EXPECT_TRUE(e.empty());
}

// from_triangle is from_points of the three corners, bit for bit, also when a corner has a
// NaN coordinate (skipped on the axes it spoils, as extend skips it; the finite corners stay
// inside) or every corner is NaN (empty).
TYPED_TEST(KdopTest, TriangleIsItsCornersEvenWithNaN) {
  constexpr int K = TypeParam::value;
  using D = Kdop<K>;
  Rng rng("KdopTest.TriangleIsItsCornersEvenWithNaN", 300 + K);
  const Scalar nan = std::numeric_limits<Scalar>::quiet_NaN();
  for (int it = 0; it < 500; ++it) {
    std::vector<Vec3> c = random_points(rng, 3, 1, Vec3::Zero());
    const int spoilt = it % 4;  // 0-2: that corner gets a NaN coordinate; 3: none
    if (spoilt < 3) c[static_cast<std::size_t>(spoilt)][it % 3] = nan;
    const D t = D::from_triangle(c[0], c[1], c[2]);
    const D p = D::from_points(c);
    ASSERT_EQ(std::memcmp(&t, &p, sizeof(D)), 0) << "iteration " << it;  // the slabs, bit for bit
    for (int k = 0; k < 3; ++k) {
      if (k != spoilt) {
        ASSERT_TRUE(t.contains(c[static_cast<std::size_t>(k)])) << "iteration " << it << " corner " << k;
      }
    }
  }
  const Vec3 all_nan(nan, nan, nan);
  EXPECT_TRUE(D::from_triangle(all_nan, all_nan, all_nan).empty());
}

TYPED_TEST(KdopTest, ContainsItsPointsTightly) {
  constexpr int K = TypeParam::value;
  using D = Kdop<K>;
  Rng rng("KdopTest.ContainsItsPointsTightly", 100 + K);
  for (int it = 0; it < 2000; ++it) {
    const Scalar S = rng.scale(-3, 3);
    const std::vector<Vec3> pts = random_points(rng, rng.integer(1, 40), S, rng.vec(-10 * S, 10 * S));
    const D k = D::from_points(pts);
    ASSERT_FALSE(k.empty());
    for (const Vec3& p : pts) ASSERT_TRUE(k.contains(p));  // exact: same projection code
    // Tight: every slab bound is attained by a point.
    for (int j = 0; j < D::kAxes; ++j) {
      bool lo = false, hi = false;
      for (const Vec3& p : pts) {
        lo = lo || D::project(p)[j] == k.min(j);
        hi = hi || D::project(p)[j] == k.max(j);
      }
      ASSERT_TRUE(lo && hi) << "slab " << j << " not tight";
    }
    // Triangles: corners exactly, convex combinations up to rounding.
    const D t = D::from_triangle(pts[0], pts[pts.size() / 2], pts.back());
    ASSERT_TRUE(t.contains(pts[0]) && t.contains(pts[pts.size() / 2]) && t.contains(pts.back()));
    for (int s = 0; s < 10; ++s) {
      Scalar u = rng.uniform(0, 1), v = rng.uniform(0, 1);
      if (u + v > 1) u = 1 - u, v = 1 - v;
      const Vec3 x = pts[0] + u * (pts[pts.size() / 2] - pts[0]) + v * (pts.back() - pts[0]);
      ASSERT_TRUE(contains_with_slack(t, x, kSlackUlps * kEps * 3 * (x.norm() + S)));
    }
  }
}

TYPED_TEST(KdopTest, InflateIsMinkowskiSumWithBall) {
  // Every point within distance d of a contained point is contained after inflate(d), and
  // the inflation is not larger than d along any axis (normalised axes: a point pushed by d
  // along a_j lands on the new boundary).
  constexpr int K = TypeParam::value;
  using D = Kdop<K>;
  Rng rng("KdopTest.InflateIsMinkowskiSumWithBall", 200 + K);
  for (int it = 0; it < 1000; ++it) {
    const Scalar S = rng.scale(-2, 2);
    const std::vector<Vec3> pts = random_points(rng, rng.integer(1, 12), S, rng.vec(-5 * S, 5 * S));
    const Scalar d = S * rng.uniform(0.001, 2);
    D k = D::from_points(pts);
    const D before = k;
    k.inflate(d);
    for (int j = 0; j < D::kAxes; ++j) {
      ASSERT_EQ(k.min(j), before.min(j) - d);
      ASSERT_EQ(k.max(j), before.max(j) + d);
    }
    for (const Vec3& p : pts) {
      const Scalar slack = kSlackUlps * kEps * 3 * (p.norm() + d);
      // Random directions, and each axis direction (the extreme case) both ways.
      for (int s = 0; s < 20; ++s) {
        const Vec3 x = p + d * rng.unit();
        ASSERT_TRUE(contains_with_slack(k, x, slack)) << "sphere point outside after inflate";
      }
      for (int j = 0; j < D::kAxes; ++j) {
        ASSERT_TRUE(contains_with_slack(k, p + d * D::axis(j), slack));
        ASSERT_TRUE(contains_with_slack(k, p - d * D::axis(j), slack));
      }
    }
    // Tightness along each axis: from the point attaining max_j, move by d along a_j.
    for (int j = 0; j < D::kAxes; ++j) {
      for (const Vec3& p : pts) {
        if (D::project(p)[j] != before.max(j)) continue;
        const Scalar reach = D::project(p + d * D::axis(j))[j];
        ASSERT_NEAR(reach, k.max(j), kSlackUlps * kEps * 3 * (p.norm() + d));
      }
    }
  }
}

TYPED_TEST(KdopTest, SweepIsMinkowskiSumWithSegment) {
  constexpr int K = TypeParam::value;
  using D = Kdop<K>;
  Rng rng("KdopTest.SweepIsMinkowskiSumWithSegment", 300 + K);
  for (int it = 0; it < 1000; ++it) {
    const Scalar S = rng.scale(-2, 2);
    const std::vector<Vec3> pts = random_points(rng, rng.integer(1, 12), S, rng.vec(-5 * S, 5 * S));
    const Vec3 disp = rng.vec(-3 * S, 3 * S);
    D k = D::from_points(pts);
    k.sweep(disp);
    std::vector<Vec3> both = pts;
    for (const Vec3& p : pts) both.push_back(p + disp);
    // Hull of P and P + disp: the swept k-DOP must match it slab by slab (up to rounding).
    const D hull = D::from_points(both);
    for (const Vec3& p : pts) {
      const Scalar slack = kSlackUlps * kEps * 3 * (p.norm() + disp.norm());
      for (int s = 0; s <= 10; ++s) {
        const Scalar lambda = s / 10.0;
        ASSERT_TRUE(contains_with_slack(k, p + lambda * disp, slack)) << "lambda " << lambda;
      }
      for (int j = 0; j < D::kAxes; ++j) {
        ASSERT_NEAR(k.min(j), hull.min(j), slack * 4);
        ASSERT_NEAR(k.max(j), hull.max(j), slack * 4);
      }
    }
  }
}

TYPED_TEST(KdopTest, MergeContainsBoth) {
  constexpr int K = TypeParam::value;
  using D = Kdop<K>;
  Rng rng("KdopTest.MergeContainsBoth", 400 + K);
  for (int it = 0; it < 1000; ++it) {
    const Scalar S = rng.scale(-2, 2);
    const std::vector<Vec3> p1 = random_points(rng, rng.integer(1, 10), S, rng.vec(-5 * S, 5 * S));
    const std::vector<Vec3> p2 = random_points(rng, rng.integer(1, 10), S, rng.vec(-5 * S, 5 * S));
    const D a = D::from_points(p1), b = D::from_points(p2);
    D m = a;
    m.merge(b);
    ASSERT_TRUE(m.contains(a) && m.contains(b));
    for (const Vec3& p : p1) ASSERT_TRUE(m.contains(p));
    for (const Vec3& p : p2) ASSERT_TRUE(m.contains(p));
    ASSERT_TRUE(m.overlaps(a) && m.overlaps(b));
  }
}

TYPED_TEST(KdopTest, OverlapIsConservative) {
  constexpr int K = TypeParam::value;
  using D = Kdop<K>;
  Rng rng("KdopTest.OverlapIsConservative", 500 + K);
  long separated = 0;
  for (int it = 0; it < 3000; ++it) {
    const Scalar S = rng.scale(-2, 2);
    std::vector<Vec3> p1 = random_points(rng, rng.integer(1, 8), S, rng.vec(-2 * S, 2 * S));
    std::vector<Vec3> p2 = random_points(rng, rng.integer(1, 8), S, rng.vec(-2 * S, 2 * S));
    // A common point (distance 0): must overlap, exactly.
    std::vector<Vec3> q2 = p2;
    q2.push_back(p1[rng.integer(0, int(p1.size()) - 1)]);
    ASSERT_TRUE(D::from_points(p1).overlaps(D::from_points(q2)));
    ASSERT_TRUE(D::from_points(q2).overlaps(D::from_points(p1)));
    // Two points within distance r: inflating both sets by r/2 (+ rounding) must overlap.
    const Scalar r = S * rng.uniform(1e-6, 1);
    std::vector<Vec3> q3 = p2;
    q3.push_back(p1[0] + r * (1 - 1e-9) * rng.unit());
    D a = D::from_points(p1), b = D::from_points(q3);
    const Scalar slack = kSlackUlps * kEps * 3 * (p1[0].norm() + r);
    a.inflate(r / 2 + slack);
    b.inflate(r / 2 + slack);
    ASSERT_TRUE(a.overlaps(b) && b.overlaps(a));
    // Symmetry of the plain test, and a consistency check with point separation.
    const D x = D::from_points(p1), y = D::from_points(p2);
    ASSERT_EQ(x.overlaps(y), y.overlaps(x));
    separated += !x.overlaps(y);
  }
  EXPECT_GT(separated, 100);  // the test also sees disjoint pairs
  // Touching slabs overlap (closed sets).
  const D a = D::from_triangle(Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0));
  const D b = D::from_triangle(Vec3(1, 0, 0), Vec3(2, 0, 0), Vec3(2, 1, 0));
  EXPECT_TRUE(a.overlaps(b));
  const D c = D::from_triangle(Vec3(std::nextafter(1.0, 2.0), 0, 0), Vec3(2, 0, 0), Vec3(2, 1, 0));
  EXPECT_FALSE(a.overlaps(c));
}

TEST(Kdop6, IsAnAxisAlignedBox) {
  Rng rng("Kdop6.IsAnAxisAlignedBox", 600);
  for (int it = 0; it < 2000; ++it) {
    const std::vector<Vec3> p1 = random_points(rng, rng.integer(1, 6), 1, rng.vec(-2, 2));
    const std::vector<Vec3> p2 = random_points(rng, rng.integer(1, 6), 1, rng.vec(-2, 2));
    Eigen::AlignedBox3d b1, b2;
    for (const Vec3& p : p1) b1.extend(p);
    for (const Vec3& p : p2) b2.extend(p);
    ASSERT_EQ(Kdop<6>::from_points(p1).overlaps(Kdop<6>::from_points(p2)), b1.intersects(b2));
  }
}

TEST(Kdop18, CullsBetterThanAnAabbOnDiagonalSlivers) {
  // Two thin parallel sticks along (1,1,0), side by side: their AABBs overlap, the diagonal
  // slabs of the 14-, 18- and 26-DOPs separate them.
  const std::vector<Vec3> s1{Vec3(0, 0, 0), Vec3(1, 1, 0)};
  const std::vector<Vec3> s2{Vec3(0.2, 0, 0), Vec3(1.2, 1, 0)};
  EXPECT_TRUE(Kdop<6>::from_points(s1).overlaps(Kdop<6>::from_points(s2)));
  EXPECT_FALSE(Kdop<14>::from_points(s1).overlaps(Kdop<14>::from_points(s2)));  // (1,-1,+-1)
  EXPECT_FALSE(Kdop<18>::from_points(s1).overlaps(Kdop<18>::from_points(s2)));
  EXPECT_FALSE(Kdop<26>::from_points(s1).overlaps(Kdop<26>::from_points(s2)));
}

}  // namespace
}  // namespace crumple::geometry
