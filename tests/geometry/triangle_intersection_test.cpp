/// Triangle-triangle intersection against an exact, independent oracle.
///
/// Oracle: closed triangles A and B intersect iff the linear system
///   sum_i l_i a_i - sum_j m_j b_j = 0,  sum l = 1,  sum m = 1,  l, m >= 0
/// is feasible. A feasible system of this form has a basic feasible solution (a vertex of the
/// polytope), whose support is a set of linearly independent columns; so we enumerate every
/// column subset, solve it exactly by fraction-free (Bareiss) Gauss-Jordan elimination in
/// integers and check the signs. No predicate, projection or case analysis is shared with the
/// implementation. Inputs are integer points (exact oracle), mapped to doubles by an exact
/// power-of-two scale and a translation (both leave the answer unchanged), which makes the
/// double-precision filter fail on the degenerate cases and exercises the exact fallback.

#include <crumple/geometry/triangle_intersection.hpp>

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <string>

#include "geometry_test_support.hpp"

namespace crumple::geometry {
namespace {

__extension__ typedef __int128 Int128;

using test::json_case;
using test::Rng;

using I3 = std::array<std::int64_t, 3>;
using ITri = std::array<I3, 3>;

/// Feasibility of the barycentric system above, exact in `Int` (int64_t for coordinates up to
/// ~100, __int128 up to ~2^14: every entry met is a minor of the 5x7 system).
template <class Int>
bool oracle_intersect(const ITri& a, const ITri& b) {
  Int m[5][7] = {};
  for (int r = 0; r < 3; ++r) {
    for (int i = 0; i < 3; ++i) {
      m[r][i] = a[i][r];
      m[r][3 + i] = -b[i][r];
    }
  }
  for (int i = 0; i < 3; ++i) m[3][i] = 1, m[4][3 + i] = 1;
  m[3][6] = 1, m[4][6] = 1;  // right-hand side
  for (int mask = 1; mask < 64; ++mask) {
    if ((mask & 7) == 0 || (mask & 56) == 0) continue;  // needs some l and some m
    int cols[7], k = 0;
    for (int c = 0; c < 6; ++c) {
      if (mask & (1 << c)) cols[k++] = c;
    }
    cols[k] = 6;
    Int t[5][7];
    for (int r = 0; r < 5; ++r) {
      for (int j = 0; j <= k; ++j) t[r][j] = m[r][cols[j]];
    }
    Int prev = 1;
    bool independent = true;
    for (int col = 0; col < k && independent; ++col) {
      int piv = -1;
      for (int r = col; r < 5; ++r) {
        if (t[r][col] != 0) {
          piv = r;
          break;
        }
      }
      if (piv < 0) {
        independent = false;
        break;
      }
      for (int j = 0; j <= k; ++j) std::swap(t[piv][j], t[col][j]);
      for (int r = 0; r < 5; ++r) {
        if (r == col) continue;
        for (int j = 0; j <= k; ++j) {
          if (j == col) continue;
          const Int num = t[col][col] * t[r][j] - t[r][col] * t[col][j];
          if (num % prev != 0) std::abort();  // Bareiss divisions are exact; oracle bug
          t[r][j] = num / prev;
        }
        t[r][col] = 0;
      }
      prev = t[col][col];
    }
    if (!independent) continue;
    bool consistent = true;
    for (int r = k; r < 5; ++r) consistent = consistent && t[r][k] == 0;
    if (!consistent) continue;
    // Now t[i][i] == prev for i < k and x_i = t[i][k] / prev.
    bool nonnegative = true;
    for (int i = 0; i < k; ++i) {
      nonnegative = nonnegative && !((t[i][k] > 0 && prev < 0) || (t[i][k] < 0 && prev > 0));
    }
    if (nonnegative) return true;
  }
  return false;
}

int orient3d_int(const I3& a, const I3& b, const I3& c, const I3& d) {
  const Int128 ux = b[0] - a[0], uy = b[1] - a[1], uz = b[2] - a[2];
  const Int128 vx = c[0] - a[0], vy = c[1] - a[1], vz = c[2] - a[2];
  const Int128 wx = d[0] - a[0], wy = d[1] - a[1], wz = d[2] - a[2];
  const Int128 det = ux * (vy * wz - vz * wy) + uy * (vz * wx - vx * wz) + uz * (vx * wy - vy * wx);
  return (det > 0) - (det < 0);
}

bool degenerate_int(const ITri& t) {
  const I3 u{t[1][0] - t[0][0], t[1][1] - t[0][1], t[1][2] - t[0][2]};
  const I3 v{t[2][0] - t[0][0], t[2][1] - t[0][1], t[2][2] - t[0][2]};
  return u[1] * v[2] - u[2] * v[1] == 0 && u[2] * v[0] - u[0] * v[2] == 0 &&
         u[0] * v[1] - u[1] * v[0] == 0;
}

/// Integer -> double with an exact power-of-two scale and translation.
struct Embedding {
  int scale_exp;
  double offset;
  Vec3 operator()(const I3& p) const {
    return Vec3(std::ldexp(double(p[0]), scale_exp) + offset,
                std::ldexp(double(p[1]), scale_exp) + offset,
                std::ldexp(double(p[2]), scale_exp) + offset);
  }
};

Embedding random_embedding(Rng& rng) {
  switch (rng.integer(0, 3)) {
    case 0: return {0, 0.0};
    case 1: return {-30, 0.0};
    case 2: return {0, std::ldexp(1.0, 30)};   // far from the origin: the filter fails often
    default: return {-20, -std::ldexp(1.0, 10)};
  }
}

std::string dump(const std::array<Vec3, 3>& a, const std::array<Vec3, 3>& b) {
  return json_case("triangle_triangle", {a[0], a[1], a[2], b[0], b[1], b[2]});
}

struct Stats {
  long cases = 0, intersecting = 0, coplanar = 0, degenerate = 0, failures = 0;
};

/// Checks one integer configuration in one embedding; `Int` is the oracle's integer type.
template <class Int>
void check_case(Stats& st, const ITri& ia, const ITri& ib, const Embedding& emb) {
  ++st.cases;
  const std::array<Vec3, 3> a{emb(ia[0]), emb(ia[1]), emb(ia[2])};
  const std::array<Vec3, 3> b{emb(ib[0]), emb(ib[1]), emb(ib[2])};
  const bool want = oracle_intersect<Int>(ia, ib);
  const bool deg = degenerate_int(ia) || degenerate_int(ib);
  const bool coplanar = !degenerate_int(ia) && !degenerate_int(ib) &&
                        orient3d_int(ia[0], ia[1], ia[2], ib[0]) == 0 &&
                        orient3d_int(ia[0], ia[1], ia[2], ib[1]) == 0 &&
                        orient3d_int(ia[0], ia[1], ia[2], ib[2]) == 0;
  st.intersecting += want;
  st.coplanar += coplanar && want;
  st.degenerate += deg;

  std::string problem;
  const TriangleIntersection r = triangle_triangle_intersection(a[0], a[1], a[2], b[0], b[1], b[2]);
  if (r.intersects != want) problem += " intersects=" + std::to_string(r.intersects);
  if ((r.piercing == Piercing::None) != !r.intersects) problem += " piercing/None mismatch";
  if ((r.piercing == Piercing::Coplanar) != (want && coplanar)) problem += " Coplanar flag wrong";
  const bool edge_piercing = r.piercing == Piercing::EdgeOfFirst || r.piercing == Piercing::EdgeOfSecond;
  if (edge_piercing != (r.edge >= 0 && r.edge < 3)) problem += " edge index wrong";
  if (r.piercing == Piercing::EdgeOfFirst) {
    // The reported side must itself meet the other triangle (oracle on a degenerate triangle).
    const ITri side{ia[r.edge], ia[(r.edge + 1) % 3], ia[(r.edge + 1) % 3]};
    if (!oracle_intersect<Int>(side, ib)) problem += " reported side of A misses B";
  } else if (r.piercing == Piercing::EdgeOfSecond) {
    const ITri side{ib[r.edge], ib[(r.edge + 1) % 3], ib[(r.edge + 1) % 3]};
    if (!oracle_intersect<Int>(ia, side)) problem += " reported side of B misses A";
  }
  // Symmetry and corner-order invariance.
  const TriangleIntersection s = triangle_triangle_intersection(b[0], b[1], b[2], a[0], a[1], a[2]);
  if (s.intersects != want) problem += " swapped disagrees";
  if ((s.piercing == Piercing::Coplanar) != (r.piercing == Piercing::Coplanar)) problem += " swapped Coplanar";
  // triangles_intersect has its own path for pairs in general position: in both orders, with
  // the corners as given and permuted.
  if (triangles_intersect(a[0], a[1], a[2], b[0], b[1], b[2]) != want) problem += " triangles_intersect disagrees";
  if (triangles_intersect(b[0], b[1], b[2], a[0], a[1], a[2]) != want) problem += " swapped triangles_intersect";
  if (triangles_intersect(a[2], a[1], a[0], b[1], b[2], b[0]) != want) problem += " permuted disagrees";
  // The sub-tests exported beside it.
  for (int k = 0; k < 3; ++k) {
    const ITri side{ia[k], ia[(k + 1) % 3], ia[(k + 1) % 3]};
    const bool side_want = oracle_intersect<Int>(side, ib);
    if (segment_triangle_intersect(a[k], a[(k + 1) % 3], b[0], b[1], b[2]) != side_want) {
      problem += " segment_triangle_intersect(side " + std::to_string(k) + ")";
    }
    const ITri other{ib[k], ib[(k + 1) % 3], ib[(k + 1) % 3]};
    if (segments_intersect(a[k], a[(k + 1) % 3], b[k], b[(k + 1) % 3]) !=
        oracle_intersect<Int>(side, other)) {
      problem += " segments_intersect(" + std::to_string(k) + ")";
    }
  }
  if (!problem.empty() && ++st.failures <= 8) {
    ADD_FAILURE() << "oracle says " << want << ";" << problem << "\n  input: " << dump(a, b);
  }
}

I3 random_point(Rng& rng, int lim) {
  return {rng.integer(-lim, lim), rng.integer(-lim, lim), rng.integer(-lim, lim)};
}

void report(const char* name, const Stats& st) {
  std::printf("[ info     ] %-28s %6ld cases: %ld intersecting, %ld coplanar overlaps, %ld with a "
              "degenerate triangle\n",
              name, st.cases, st.intersecting, st.coplanar, st.degenerate);
}

TEST(TriangleIntersection, MatchesOracleOnSmallGrid) {
  // Coordinates in [-2, 2]: dense in coincidences, collinear and coplanar configurations.
  Rng rng("TriangleIntersection.MatchesOracleOnSmallGrid", 1001);
  Stats st;
  for (int i = 0; i < 12000; ++i) {
    const ITri a{random_point(rng, 2), random_point(rng, 2), random_point(rng, 2)};
    const ITri b{random_point(rng, 2), random_point(rng, 2), random_point(rng, 2)};
    check_case<std::int64_t>(st, a, b, random_embedding(rng));
  }
  report("small grid", st);
  EXPECT_EQ(st.failures, 0);
  EXPECT_GT(st.intersecting, 1000);
  EXPECT_GT(st.coplanar, 5);  // the coplanar family below has many more
}

TEST(TriangleIntersection, MatchesOracleGeneric) {
  Rng rng("TriangleIntersection.MatchesOracleGeneric", 1002);
  Stats st;
  for (int i = 0; i < 8000; ++i) {
    const ITri a{random_point(rng, 60), random_point(rng, 60), random_point(rng, 60)};
    const I3 shift = random_point(rng, 30);
    ITri b{random_point(rng, 30), random_point(rng, 30), random_point(rng, 30)};
    for (auto& p : b) {
      for (int k = 0; k < 3; ++k) p[k] += shift[k];
    }
    check_case<std::int64_t>(st, a, b, random_embedding(rng));
  }
  report("generic", st);
  EXPECT_EQ(st.failures, 0);
  EXPECT_GT(st.intersecting, 1000);
}

TEST(TriangleIntersection, MatchesOracleSharedFeaturesAndCoplanar) {
  Rng rng("TriangleIntersection.MatchesOracleSharedFeaturesAndCoplanar", 1003);
  Stats st;
  for (int i = 0; i < 9000; ++i) {
    ITri a{random_point(rng, 8), random_point(rng, 8), random_point(rng, 8)};
    ITri b{random_point(rng, 8), random_point(rng, 8), random_point(rng, 8)};
    switch (i % 3) {
      case 0:  // shared vertex (mesh neighbours)
        b[rng.integer(0, 2)] = a[rng.integer(0, 2)];
        break;
      case 1: {  // shared edge (a hinge), possibly folded flat onto each other
        const int k = rng.integer(0, 2);
        b[0] = a[k], b[1] = a[(k + 1) % 3];
        if (rng.coin()) std::swap(b[0], b[1]);
        break;
      }
      default: {  // all six points on one plane o + i u + j v
        const I3 o = random_point(rng, 4), u = random_point(rng, 2), v = random_point(rng, 2);
        for (ITri* t : {&a, &b}) {
          for (I3& p : *t) {
            const int s = rng.integer(-3, 3), q = rng.integer(-3, 3);
            for (int k = 0; k < 3; ++k) p[k] = o[k] + s * u[k] + q * v[k];
          }
        }
      }
    }
    check_case<std::int64_t>(st, a, b, random_embedding(rng));
  }
  report("shared features / coplanar", st);
  EXPECT_EQ(st.failures, 0);
  EXPECT_GT(st.coplanar, 500);
}

TEST(TriangleIntersection, MatchesOracleTouchingAndNearTouching) {
  // A corner of B placed exactly on a corner, a side or the interior of A (coordinates of A
  // are multiples of 6 so that midpoints and centroids are integers), then moved by one unit
  // (relative 1e-3 .. 1e-4 of the size) or not at all.
  Rng rng("TriangleIntersection.MatchesOracleTouchingAndNearTouching", 1004);
  Stats st;
  for (int i = 0; i < 8000; ++i) {
    ITri a;
    for (I3& p : a) p = random_point(rng, 1000);
    for (I3& p : a) {
      for (auto& x : p) x *= 6;
    }
    I3 touch;
    const int where = i % 3;
    const int k = rng.integer(0, 2);
    for (int m = 0; m < 3; ++m) {
      if (where == 0) touch[m] = a[k][m];
      if (where == 1) touch[m] = (a[k][m] + a[(k + 1) % 3][m]) / 2;
      if (where == 2) touch[m] = (a[0][m] + a[1][m] + a[2][m]) / 3;
    }
    if (i % 2 == 1) touch[rng.integer(0, 2)] += rng.coin() ? 1 : -1;
    ITri b{touch, random_point(rng, 6000), random_point(rng, 6000)};
    if (rng.coin()) {
      // Keep B on one side of A's plane except for the touching corner, when possible.
      for (int j = 1; j < 3; ++j) {
        if (orient3d_int(a[0], a[1], a[2], b[j]) < 0) {
          for (int m = 0; m < 3; ++m) b[j][m] = 2 * touch[m] - b[j][m];
        }
      }
    }
    const Embedding emb = std::array{Embedding{0, 0.0}, Embedding{-12, 0.0},
                                     Embedding{0, std::ldexp(1.0, 30)},
                                     Embedding{-40, std::ldexp(1.0, -10)}}[i % 4];
    check_case<Int128>(st, a, b, emb);
  }
  report("touching / near touching", st);
  EXPECT_EQ(st.failures, 0);
  EXPECT_GT(st.intersecting, 1000);
}

TEST(TriangleIntersection, HandMadeConfigurations) {
  const Vec3 a0(0, 0, 0), a1(1, 0, 0), a2(0, 1, 0);
  const auto hit = [&](const Vec3& b0, const Vec3& b1, const Vec3& b2) {
    return triangle_triangle_intersection(a0, a1, a2, b0, b1, b2);
  };
  const double tiny = std::ldexp(1.0, -60);
  // A corner of B touching the interior of A from above; lifted by 2^-60; pushed through.
  EXPECT_TRUE(hit(Vec3(0.25, 0.25, 0), Vec3(0.25, 0.25, 1), Vec3(1, 1, 1)).intersects);
  EXPECT_FALSE(hit(Vec3(0.25, 0.25, tiny), Vec3(0.25, 0.25, 1), Vec3(1, 1, 1)).intersects);
  const TriangleIntersection through = hit(Vec3(0.25, 0.25, -tiny), Vec3(0.25, 0.25, 1), Vec3(1, 1, 1));
  EXPECT_TRUE(through.intersects);
  EXPECT_EQ(through.piercing, Piercing::EdgeOfSecond);
  // Edge-edge crossing of two vertical/horizontal triangles.
  const TriangleIntersection cross = hit(Vec3(0.5, -1, 0.5), Vec3(0.5, 1, -0.5), Vec3(0.5, 1, 0.5));
  EXPECT_TRUE(cross.intersects);
  EXPECT_EQ(cross.piercing, Piercing::EdgeOfFirst);
  EXPECT_EQ(cross.edge, 0);  // side a0-a1 passes through B
  // Shared vertex only, B leaning away: touching at the shared corner counts.
  EXPECT_TRUE(hit(Vec3(0, 0, 0), Vec3(-1, 0, 1), Vec3(0, -1, 1)).intersects);
  // Shared edge (hinge).
  EXPECT_TRUE(hit(Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, -1, 1)).intersects);
  // Coplanar: overlapping, one inside the other, touching at a corner, disjoint by 2^-60.
  EXPECT_EQ(hit(Vec3(0.5, 0.5, 0), Vec3(-1, 0.2, 0), Vec3(0.2, -1, 0)).piercing, Piercing::Coplanar);
  EXPECT_EQ(hit(Vec3(0.1, 0.1, 0), Vec3(0.2, 0.1, 0), Vec3(0.1, 0.2, 0)).piercing, Piercing::Coplanar);
  EXPECT_EQ(hit(Vec3(-1, -1, 0), Vec3(3, -1, 0), Vec3(-1, 3, 0)).piercing, Piercing::Coplanar);
  EXPECT_TRUE(hit(Vec3(1, 0, 0), Vec3(2, 0, 0), Vec3(2, 1, 0)).intersects);
  const double one_up = std::nextafter(1.0, 2.0), half_up = std::nextafter(0.5, 1.0);
  EXPECT_FALSE(hit(Vec3(one_up, 0, 0), Vec3(2, 0, 0), Vec3(2, 1, 0)).intersects);
  EXPECT_FALSE(hit(Vec3(half_up, half_up, 0), Vec3(2, 0.5, 0), Vec3(0.5, 2, 0)).intersects);
  EXPECT_TRUE(hit(Vec3(0.5, 0.5, 0), Vec3(2, 0.5, 0), Vec3(0.5, 2, 0)).intersects);
  // Parallel planes: disjoint.
  EXPECT_FALSE(hit(Vec3(0, 0, tiny), Vec3(1, 0, tiny), Vec3(0, 1, tiny)).intersects);
  // Degenerate B (a segment) through A, along A, beside A; a point on A.
  const TriangleIntersection seg = hit(Vec3(0.2, 0.2, -1), Vec3(0.2, 0.2, 1), Vec3(0.2, 0.2, 0.5));
  EXPECT_TRUE(seg.intersects);
  EXPECT_EQ(seg.piercing, Piercing::EdgeOfSecond);
  EXPECT_TRUE(hit(Vec3(-1, 0.5, 0), Vec3(2, 0.5, 0), Vec3(0.5, 0.5, 0)).intersects);
  EXPECT_FALSE(hit(Vec3(-1, 2, 0), Vec3(2, 2, 0), Vec3(0.5, 2, 0)).intersects);
  EXPECT_TRUE(hit(Vec3(0.3, 0.3, 0), Vec3(0.3, 0.3, 0), Vec3(0.3, 0.3, 0)).intersects);
  EXPECT_FALSE(hit(Vec3(0.3, 0.3, tiny), Vec3(0.3, 0.3, tiny), Vec3(0.3, 0.3, tiny)).intersects);
  // Both degenerate: crossing segments, skew segments.
  EXPECT_TRUE(triangles_intersect(Vec3(0, 0, 0), Vec3(2, 2, 0), Vec3(1, 1, 0), Vec3(0, 2, 0),
                                  Vec3(2, 0, 0), Vec3(2, 0, 0)));
  EXPECT_FALSE(triangles_intersect(Vec3(0, 0, 0), Vec3(2, 2, 0), Vec3(1, 1, 0), Vec3(0, 2, tiny),
                                   Vec3(2, 0, tiny), Vec3(2, 0, tiny)));
}

}  // namespace
}  // namespace crumple::geometry
