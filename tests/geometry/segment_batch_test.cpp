// segment_segment_x4 against segment_segment, bit for bit: the exact detectors' narrow phase
// uses the batch and `naive` the scalar kernel, and their distances must be identical; so must
// the contact's distance and normal that the batch computes in its lanes.

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
using Case = std::array<Vec3, 4>;  // p0, p1, q0, q1

// Every case of `make`, four to a batch: the lanes give the scalar kernel's bits. Returns the
// number of mismatching lanes (the first few are printed). Only on a CPU with AVX2.
int mismatches(int cases, const std::function<Case(int)>& make) {
  int bad = 0;
  for (int i = 0; i < cases; i += 4) {
    SegmentBatch batch;
    std::array<Case, 4> in;
    std::array<SegmentSegmentResult, 4> want;
    for (std::size_t k = 0; k < 4; ++k) {
      in[k] = make(i + static_cast<int>(k));
      batch.set(k, in[k][0], in[k][1], in[k][2], in[k][3]);
      want[k] = segment_segment(in[k][0], in[k][1], in[k][2], in[k][3]);
    }
    const SegmentBatchResult got = segment_segment_x4(batch);
    for (std::size_t k = 0; k < 4; ++k) {
      // What narrow::edge_edge_contact computes from the scalar result.
      const Vec3 gap = want[k].closest1 - want[k].closest0;
      const Scalar gap_norm = gap.norm();
      bool same = bits(got.sqr_distance[k]) == bits(want[k].sqr_distance) && bits(got.s[k]) == bits(want[k].s) &&
                  bits(got.t[k]) == bits(want[k].t) &&
                  bits(got.distance[k]) == bits(std::sqrt(want[k].sqr_distance)) &&
                  bits(got.gap_norm[k]) == bits(gap_norm);
      if (gap_norm > 0) {
        const Vec3 normal = gap / gap_norm;
        for (int i = 0; i < 3; ++i) same = same && bits(got.normal[static_cast<std::size_t>(i)][k]) == bits(normal[i]);
      }
      if (same) continue;
      if (++bad <= 5) {
        const auto& [x0, x1, x2, x3] = in[k];
        ADD_FAILURE() << "lane " << k << ": " << test::json_case("segment_segment", {x0, x1, x2, x3}) << "\n  want d2 "
                      << want[k].sqr_distance << " s " << want[k].s << " t " << want[k].t << " |gap| " << gap_norm
                      << "\n  got  d2 " << got.sqr_distance[k] << " s " << got.s[k] << " t " << got.t[k] << " |gap| "
                      << got.gap_norm[k] << " (or its distance or normal differs)";
      }
    }
  }
  return bad;
}

class SegmentBatchLanes : public test::LanesTest {};

TEST_F(SegmentBatchLanes, SameBitsGeneric) {
  Rng rng("SegmentBatchLanes.SameBitsGeneric", 9101);
  EXPECT_EQ(mismatches(200000, [&](int) {
              const Scalar S = rng.scale(-3, 3);
              const Vec3 o = rng.coin() ? Vec3::Zero() : rng.vec(-10 * S, 10 * S);
              const Scalar l1 = rng.coin() ? 1.0 : 0.05, l2 = rng.coin() ? 1.0 : 0.05;
              const Vec3 p0 = o + rng.vec(-S, S), q0 = o + rng.vec(-S, S);
              return Case{p0, p0 + l1 * rng.vec(-S, S), q0, q0 + l2 * rng.vec(-S, S)};
            }),
            0);
}

TEST_F(SegmentBatchLanes, SameBitsDegenerate) {
  Rng rng("SegmentBatchLanes.SameBitsDegenerate", 9102);
  EXPECT_EQ(mismatches(80000, [&](int i) {
              const Scalar S = rng.scale(-3, 3);
              const Vec3 o = rng.vec(-5 * S, 5 * S);
              const Vec3 a = o + rng.vec(-S, S), b = o + rng.vec(-S, S), c = o + rng.vec(-S, S),
                         d = o + rng.vec(-S, S);
              switch (i % 8) {
                case 0: return Case{a, a, c, d};  // P is a point
                case 1: return Case{a, b, c, c};  // Q is a point
                case 2: return Case{a, a, c, c};  // both points
                case 3: return Case{a, a, a, a};  // all coincide
                case 4: return Case{a, b, a, d};  // shared start
                case 5: return Case{a, b, c, b};  // shared end
                case 6: return Case{a, b, b, a};  // same segment, reversed
                default: {                        // crossing: Q passes through a point of P
                  const Vec3 x = a + rng.uniform(0, 1) * (b - a);
                  const Scalar mu = rng.uniform(0, 1);
                  return Case{a, b, x - mu * (c - d), x + (1 - mu) * (c - d)};
                }
              }
            }),
            0);
}

TEST_F(SegmentBatchLanes, SameBitsNearParallel) {
  Rng rng("SegmentBatchLanes.SameBitsNearParallel", 9103);
  const std::array<Scalar, 7> angles{1e-4, 1e-6, 1e-8, 1e-10, 1e-12, 0.0, 1e-14};
  EXPECT_EQ(mismatches(140000, [&](int i) {
              const Scalar theta = angles[static_cast<std::size_t>(i) % angles.size()];
              const Scalar S = rng.scale(-3, 3);
              const Vec3 o = rng.coin() ? Vec3::Zero() : rng.vec(-10 * S, 10 * S);
              const Vec3 d = rng.unit(), m = rng.orthogonal_unit(d), n = rng.orthogonal_unit(d);
              Vec3 d2 = std::cos(theta) * d + std::sin(theta) * m;
              if (rng.coin()) d2 = -d2;
              const Scalar l1 = S * rng.uniform(0.1, 1), l2 = S * rng.uniform(0.1, 1);
              const Vec3 p0 = o + rng.vec(-S, S);
              const int k = rng.integer(0, 16);
              const Scalar sep = k == 16 ? 0.0 : S * std::pow(10.0, -k);
              const Vec3 q0 = p0 + l1 * rng.uniform(-1.5, 1.5) * d + sep * n;
              return Case{p0, p0 + l1 * d, q0, q0 + l2 * d2};
            }),
            0);
}

// Small integer coordinates: exact ties everywhere (roots exactly 0 or 1, H exactly 0, exactly
// parallel and collinear segments), where a lane choosing the other side of a comparison shows.
TEST_F(SegmentBatchLanes, SameBitsOnTies) {
  Rng rng("SegmentBatchLanes.SameBitsOnTies", 9104);
  EXPECT_EQ(mismatches(200000,
                       [&](int) {
                         return Case{rng.small_integer_point(), rng.small_integer_point(), rng.small_integer_point(),
                                     rng.small_integer_point()};
                       }),
            0);
}

}  // namespace
}  // namespace crumple::geometry
