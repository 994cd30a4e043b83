// point_triangle_x4 against point_triangle, bit for bit: the exact detectors' narrow phase uses
// the batch and `naive` the scalar kernel, and their contacts must be identical. So the
// distance, barycentrics and the contact's normal that narrow::vertex_face computes from the
// scalar result are compared too.

#include <crumple/geometry/distance.hpp>
#include <crumple/geometry/kernel_batch.hpp>

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <functional>
#include <string>

#include "geometry_test_support.hpp"

namespace crumple::geometry {
namespace {

using test::bits;
using test::Rng;
using Case = std::array<Vec3, 4>;  // p, a, b, c

// Every case of `make`, four to a batch: the lanes give the scalar kernel's bits and the
// contact's. Returns the number of mismatching lanes (the first few are printed).
int mismatches(int cases, const std::function<Case(int)>& make) {
  int bad = 0;
  for (int i = 0; i < cases; i += 4) {
    PointTriangleBatch batch;
    std::array<Case, 4> in;
    for (std::size_t k = 0; k < 4; ++k) {
      in[k] = make(i + static_cast<int>(k));
      batch.set(k, in[k][0], in[k][1], in[k][2], in[k][3]);
    }
    const PointTriangleBatchResult got = point_triangle_x4(batch);
    for (std::size_t k = 0; k < 4; ++k) {
      const auto& [p, a, b, c] = in[k];
      const PointTriangleResult want = point_triangle(p, a, b, c);
      // What narrow::vertex_face computes from it.
      const Vec3 away = p - want.closest;
      const Scalar away_norm = away.norm();
      bool same = bits(got.sqr_distance[k]) == bits(want.sqr_distance) &&
                  bits(got.distance[k]) == bits(std::sqrt(want.sqr_distance)) &&
                  bits(got.away_norm[k]) == bits(away_norm);
      for (std::size_t j = 0; j < 3; ++j) {
        const auto jj = static_cast<Eigen::Index>(j);
        same = same && bits(got.barycentric[j][k]) == bits(want.barycentric[jj]);
        if (away_norm > 0) same = same && bits(got.normal[j][k]) == bits(away[jj] / away_norm);
      }
      if (same) continue;
      if (++bad <= 5) {
        ADD_FAILURE() << "lane " << k << ": " << test::json_case("point_triangle", {p, a, b, c}) << "\n  want d2 "
                      << want.sqr_distance << " w " << want.barycentric.transpose() << " |away| " << away_norm
                      << "\n  got  d2 " << got.sqr_distance[k] << " w " << got.barycentric[0][k] << " "
                      << got.barycentric[1][k] << " " << got.barycentric[2][k] << " |away| " << got.away_norm[k]
                      << " (or the distance or normal)";
      }
    }
  }
  return bad;
}

class PointTriangleBatchLanes : public test::LanesTest {};

TEST_F(PointTriangleBatchLanes, SameBitsGeneric) {
  Rng rng("PointTriangleBatchLanes.SameBitsGeneric", 9201);
  EXPECT_EQ(mismatches(200000, [&](int) {
              const Scalar S = rng.scale(-3, 3);
              const Vec3 o = rng.coin() ? Vec3::Zero() : rng.vec(-10 * S, 10 * S);
              const Vec3 a = o + rng.vec(-S, S), b = o + rng.vec(-S, S), c = o + rng.vec(-S, S);
              // The point near the triangle's plane (every region) or anywhere around it.
              const Vec3 n = (b - a).cross(c - a).normalized();
              const Vec3 p = rng.coin() ? Vec3(o + rng.vec(-2 * S, 2 * S))
                                        : Vec3(a + rng.uniform(-1, 2) * (b - a) + rng.uniform(-1, 2) * (c - a) +
                                               S * rng.uniform(-1e-3, 1e-3) * n);
              return Case{p, a, b, c};
            }),
            0);
}

TEST_F(PointTriangleBatchLanes, SameBitsDegenerate) {
  Rng rng("PointTriangleBatchLanes.SameBitsDegenerate", 9202);
  EXPECT_EQ(mismatches(80000, [&](int i) {
              const Scalar S = rng.scale(-3, 3);
              const Vec3 o = rng.vec(-5 * S, 5 * S);
              const Vec3 a = o + rng.vec(-S, S), b = o + rng.vec(-S, S), c = o + rng.vec(-S, S);
              const Vec3 p = o + rng.vec(-S, S);
              const Vec3 n = (b - a).cross(c - a).normalized();
              switch (i % 8) {
                case 0: return Case{p, a, a, a};                                     // a point
                case 1: return Case{p, a, a, c};                                     // two corners coincide
                case 2: return Case{p, a, b, a + rng.uniform(-1, 2) * (b - a)};      // collinear
                case 3: return Case{p, a, b, a + 0.5 * (b - a) + 1e-15 * S * n};     // flat, up to rounding
                case 4: return Case{p, a, b, a + 0.5 * (b - a) + 1e-12 * S * n};     // a sliver
                case 5: return Case{a, a, b, c};                                     // the point is a corner
                case 6: return Case{a + rng.uniform(0, 1) * (b - a), a, b, c};       // on a side
                default: return Case{a + 0.25 * (b - a) + 0.25 * (c - a), a, b, c};  // in the face
              }
            }),
            0);
}

// Small integer coordinates: exact ties everywhere (sides of equal length, barycentrics exactly
// 0, a point equally far from two sides, points in the plane), where a lane choosing the other
// side of a comparison shows.
TEST_F(PointTriangleBatchLanes, SameBitsOnTies) {
  Rng rng("PointTriangleBatchLanes.SameBitsOnTies", 9203);
  EXPECT_EQ(mismatches(200000,
                       [&](int) {
                         return Case{rng.small_integer_point(), rng.small_integer_point(), rng.small_integer_point(),
                                     rng.small_integer_point()};
                       }),
            0);
}

}  // namespace
}  // namespace crumple::geometry
