// triangles_intersect_x4 against triangles_intersect: both are exact, so they must agree on every
// pair, and the exact detectors' intersection query (which uses the batch) must report what
// `naive` (which uses the scalar test) reports. The lanes decide only what their filters
// certify and hand the rest to the scalar test; the tests also check that they do decide the
// pairs in general position, or the batch would be correct and useless.

#include <crumple/geometry/kernel_batch.hpp>
#include <crumple/geometry/triangle_intersection.hpp>

#include <gtest/gtest.h>

#include <array>
#include <cstdio>
#include <functional>

#include "geometry_test_support.hpp"

namespace crumple::geometry {
namespace {

using test::Rng;
using Case = std::array<Vec3, 6>;  // a0 a1 a2 b0 b1 b2

struct Tally {
  int mismatches = 0;
  int deferred = 0;  // lanes the batch left to the scalar test
  int hits = 0;      // intersecting pairs
};

// Every case of `make`, `lanes` to a batch (the unused lanes hold an intersecting pair, which
// must not be reported).
Tally run(int cases, const std::function<Case(int)>& make, std::size_t lanes = 4) {
  Tally tally;
  TrianglePairBatch batch;
  // Every lane starts with a pair that intersects in general position, so that a lane past the
  // count that got reported would show.
  for (std::size_t k = 0; k < 4; ++k) {
    batch.set(k, Vec3(0, 0, 0), Vec3(2, 0, 0), Vec3(0, 2, 0), Vec3(0.5, 0.5, -1), Vec3(0.6, 0.4, 1), Vec3(0.4, 0.7, 1));
  }
  EXPECT_EQ(triangles_intersect_x4(batch, 4), 15u);
  for (int i = 0; i < cases; i += static_cast<int>(lanes)) {
    std::array<Case, 4> in;
    for (std::size_t k = 0; k < lanes; ++k) {
      in[k] = make(i + static_cast<int>(k));
      batch.set(k, in[k][0], in[k][1], in[k][2], in[k][3], in[k][4], in[k][5]);
    }
    unsigned deferred = 0;
    const unsigned got = triangles_intersect_x4(batch, lanes, &deferred);
    EXPECT_EQ(got >> lanes, 0u) << "a lane past the count was reported";
    EXPECT_EQ(deferred >> lanes, 0u) << "a lane past the count was deferred";
    for (std::size_t k = 0; k < lanes; ++k) {
      const auto& [a0, a1, a2, b0, b1, b2] = in[k];
      const bool want = triangles_intersect(a0, a1, a2, b0, b1, b2);
      tally.hits += want ? 1 : 0;
      tally.deferred += static_cast<int>(deferred >> k & 1u);
      if (((got >> k & 1u) != 0) == want) continue;
      if (++tally.mismatches <= 5) {
        ADD_FAILURE() << "lane " << k << " of " << lanes << ": "
                      << test::json_case("triangles_intersect", {a0, a1, a2, b0, b1, b2}) << "\n  want " << want
                      << ", got " << !want << ((deferred >> k & 1u) != 0 ? " (deferred)" : " (in the lanes)");
      }
    }
  }
  return tally;
}

// Two triangles of size S around nearby centres, at a random scale and offset: about a third
// of them intersect, the others are separated by a plane or miss each other across the line
// where their planes meet.
Case generic(Rng& rng) {
  const Scalar S = rng.scale(-3, 3);
  const Vec3 o = rng.coin() ? Vec3::Zero() : rng.vec(-10 * S, 10 * S);
  const Vec3 ca = o + rng.vec(-0.3 * S, 0.3 * S), cb = o + rng.vec(-0.3 * S, 0.3 * S);
  return Case{ca + rng.vec(-S, S), ca + rng.vec(-S, S), ca + rng.vec(-S, S),
              cb + rng.vec(-S, S), cb + rng.vec(-S, S), cb + rng.vec(-S, S)};
}

class TriangleBatchLanes : public test::LanesTest {};

TEST_F(TriangleBatchLanes, AgreesInGeneralPositionAndDecidesInTheLanes) {
  Rng rng("TriangleBatchLanes.AgreesInGeneralPositionAndDecidesInTheLanes", 9301);
  const int cases = 400000;
  const Tally t = run(cases, [&](int) { return generic(rng); });
  std::printf("[ tally    ] %d pairs, %d intersect, %d left to the scalar test\n", cases, t.hits, t.deferred);
  EXPECT_EQ(t.mismatches, 0);
  // Both answers occur often (each path of the lanes is taken: plane rejections by either
  // triangle, Guigue and Devillers' hits and misses).
  EXPECT_GT(t.hits, cases / 10);
  EXPECT_LT(t.hits, cases * 9 / 10);
  // Random doubles in general position: the filters decide all but a handful.
  EXPECT_LT(t.deferred, cases / 1000) << "the lanes left " << t.deferred << " of " << cases << " pairs to the scalar test";
}

TEST_F(TriangleBatchLanes, AgreesOnPartialBatches) {
  Rng rng("TriangleBatchLanes.AgreesOnPartialBatches", 9302);
  for (std::size_t lanes = 1; lanes <= 3; ++lanes) {
    EXPECT_EQ(run(30000, [&](int) { return generic(rng); }, lanes).mismatches, 0) << lanes << " lanes";
  }
}

// What a mesh holds: triangles that share a corner or a side, touch at a point or along a
// segment, lie in one plane, or are degenerate. Most of these the lanes must defer.
TEST_F(TriangleBatchLanes, AgreesOnContactAndDegenerateConfigurations) {
  Rng rng("TriangleBatchLanes.AgreesOnContactAndDegenerateConfigurations", 9303);
  const Tally t = run(120000, [&](int i) {
    const Scalar S = rng.scale(-3, 3);
    const Vec3 o = rng.vec(-5 * S, 5 * S);
    const Vec3 a0 = o + rng.vec(-S, S), a1 = o + rng.vec(-S, S), a2 = o + rng.vec(-S, S);
    const Vec3 b1 = o + rng.vec(-S, S), b2 = o + rng.vec(-S, S);
    const Vec3 n = (a1 - a0).cross(a2 - a0);
    const Vec3 in_a = a0 + 0.25 * (a1 - a0) + 0.25 * (a2 - a0);
    switch (i % 10) {
      case 0: return Case{a0, a1, a2, a0, b1, b2};                                     // a shared corner
      case 1: return Case{a0, a1, a2, a1, a0, b2};                                     // a shared side
      case 2: return Case{a0, a1, a2, in_a, b1, b2};                                   // a corner in the face
      case 3: return Case{a0, a1, a2, a0 + rng.uniform(0, 1) * (a1 - a0), b1, b2};     // a corner on a side
      case 4: return Case{a0, a1, a2, in_a, in_a + (a1 - a0), in_a + rng.uniform(-1, 1) * (a2 - a0)};  // coplanar
      case 5: return Case{a0, a1, a2, in_a + 1e-15 * n, b1, b2};                       // within rounding of the face
      case 6: return Case{a0, a0, a2, o + rng.vec(-S, S), b1, b2};                     // two corners coincide
      case 7: return Case{a0, a1, a0 + rng.uniform(-1, 2) * (a1 - a0), o, b1, b2};     // collinear corners
      case 8: return Case{a0, a1, a2, b1, b1, b1};                                     // a point
      default: return Case{a0, a1, a2, a0 + 2 * (a1 - a0), a1 + rng.uniform(0.1, 1) * n, b2};  // crossing a side's line
    }
  });
  std::printf("[ tally    ] 120000 pairs, %d intersect, %d left to the scalar test\n", t.hits, t.deferred);
  EXPECT_EQ(t.mismatches, 0);
  EXPECT_GT(t.deferred, 0);
}

// Small integer coordinates: coplanar corners, shared corners and touching everywhere, where a
// sign the filter should not certify, or a tie taken the wrong way, shows.
TEST_F(TriangleBatchLanes, AgreesOnIntegerTies) {
  Rng rng("TriangleBatchLanes.AgreesOnIntegerTies", 9304);
  EXPECT_EQ(run(200000,
                [&](int) {
                  Case c;
                  for (Vec3& p : c) p = rng.small_integer_point();
                  return c;
                })
                .mismatches,
            0);
}

}  // namespace
}  // namespace crumple::geometry
