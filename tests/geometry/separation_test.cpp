// The plane and line rejections of the exact detectors' narrow phase (separation.hpp): the
// scalar test only rejects pairs that are further apart than the pad (checked against the
// exact distances), and the four-lane test gives the scalar verdicts bit for bit, on random,
// degenerate and threshold inputs (the narrow phase uses the lanes where the CPU has AVX2, the
// scalar test elsewhere, and both must sift the same sub-pairs).

#include <crumple/geometry/distance.hpp>
#include <crumple/geometry/kernel_batch.hpp>
#include <crumple/geometry/separation.hpp>

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <functional>
#include <limits>
#include <vector>

#include "geometry_test_support.hpp"

namespace crumple::geometry {
namespace {

using test::Rng;
using Case = std::array<Vec3, 4>;  // plane: p, a, b, c; line: p0, p1, q0, q1

Separation separation(bool line, const Case& c) {
  return line ? line_separation(c[0], c[1], c[2], c[3]) : plane_separation(c[0], c[1], c[2], c[3]);
}

/// The exact distance that the test bounds from below.
Scalar distance(bool line, const Case& c) {
  return std::sqrt(line ? segment_segment(c[0], c[1], c[2], c[3]).sqr_distance
                        : point_triangle(c[0], c[1], c[2], c[3]).sqr_distance);
}

/// A pad at which the scalar test is close to changing its verdict: the separation |wn| / |n|
/// (less the margin), nudged by a few ulps either way; or a random pad around the points' scale.
Scalar pad_for(Rng& rng, const Separation& s, Scalar scale) {
  const Scalar nn = s.n.squaredNorm();
  const Scalar clear = std::abs(s.wn) - 1e-13 * s.size;
  if (rng.coin() && nn > 0 && clear > 0 && std::isfinite(clear / std::sqrt(nn))) {
    Scalar pad = clear / std::sqrt(nn);
    for (int k = rng.integer(-3, 3); k != 0; k += k > 0 ? -1 : 1) {
      pad = std::nextafter(pad, k > 0 ? std::numeric_limits<Scalar>::infinity() : 0.0);
    }
    return pad;
  }
  return scale * std::pow(10.0, rng.uniform(-4, 1));
}

#if CRUMPLE_SEPARATION_LANES
/// Every case of `make`, four to a call; each call is made at four pads, one drawn by `pad_for`
/// from each lane's case (so that every lane is tested at a pad near its own threshold).
/// Returns the number of lanes whose verdict differs from the scalar test's (the first few are
/// printed). The points are the 16 elements of a vector of exactly that size, so that a read
/// past a point's three coordinates would leave the allocation (AddressSanitizer reports it).
template <bool kLine>
int mismatches(Rng& rng, int cases, const std::function<Case(int)>& make) {
  int bad = 0;
  for (int i = 0; i < cases; i += 4) {
    std::vector<Vec3> store(16);
    std::array<Case, 4> in;
    std::array<SeparationPoints, 4> points;
    for (std::size_t l = 0; l < 4; ++l) {
      in[l] = make(i + static_cast<int>(l));
      for (std::size_t k = 0; k < 4; ++k) {
        store[4 * l + k] = in[l][k];
        points[l][k] = &store[4 * l + k];
      }
    }
    for (std::size_t own = 0; own < 4; ++own) {
      const Scalar scale = (in[own][0] - in[own][1]).cwiseAbs().maxCoeff() + 1e-300;
      const Scalar pad = pad_for(rng, separation(kLine, in[own]), scale);
      const unsigned got = beyond_x4<kLine>(points, pad);
      for (std::size_t l = 0; l < 4; ++l) {
        const bool want = beyond(separation(kLine, in[l]), pad);
        if (((got >> l) & 1u) == (want ? 1u : 0u)) continue;
        if (++bad <= 5) {
          const auto& [x0, x1, x2, x3] = in[l];
          ADD_FAILURE() << "lane " << l << " at pad " << pad << ": "
                        << test::json_case(kLine ? "line" : "plane", {x0, x1, x2, x3}) << "\n  scalar says "
                        << (want ? "beyond" : "within") << ", the lanes the opposite";
        }
      }
    }
  }
  return bad;
}

class SeparationLanes : public test::LanesTest {};

Case generic(Rng& rng) {
  const Scalar S = rng.scale(-3, 3);
  const Vec3 o = rng.coin() ? Vec3::Zero() : rng.vec(-10 * S, 10 * S);
  return Case{o + rng.vec(-S, S), o + rng.vec(-S, S), o + rng.vec(-S, S), o + rng.vec(-S, S)};
}

TEST_F(SeparationLanes, SameVerdictsGeneric) {
  Rng rng("SeparationLanes.SameVerdictsGeneric", 9301);
  EXPECT_EQ(mismatches<false>(rng, 100000, [&](int) { return generic(rng); }), 0);
  EXPECT_EQ(mismatches<true>(rng, 100000, [&](int) { return generic(rng); }), 0);
}

// Close pairs as a cloth's are: a point just above a triangle, two edges just apart, at
// distances around the pad (the verdicts then hinge on the last bits).
TEST_F(SeparationLanes, SameVerdictsNearContact) {
  Rng rng("SeparationLanes.SameVerdictsNearContact", 9302);
  const auto near = [&](bool line) {
    const Scalar S = rng.scale(-2, 2);
    const Vec3 o = rng.vec(-100 * S, 100 * S);
    const Vec3 d = rng.unit(), m = rng.orthogonal_unit(d);
    const Vec3 n = d.cross(m);
    const Scalar gap = S * std::pow(10.0, rng.uniform(-6, -1)) * (rng.coin() ? 1 : -1);
    if (line) {
      const Vec3 p0 = o + rng.vec(-S, S);
      const Vec3 q0 = p0 + gap * n + rng.uniform(-S, S) * d;
      return Case{p0, p0 + S * d, q0, q0 + S * (m + rng.uniform(-0.5, 0.5) * d)};
    }
    const Vec3 a = o, b = o + S * d, c = o + S * m;
    return Case{o + rng.uniform(0, 0.5) * S * d + rng.uniform(0, 0.5) * S * m + gap * n, a, b, c};
  };
  EXPECT_EQ(mismatches<false>(rng, 100000, [&](int) { return near(false); }), 0);
  EXPECT_EQ(mismatches<true>(rng, 100000, [&](int) { return near(true); }), 0);
}

// Parallel lines and degenerate triangles (n = 0: never beyond), coincident points, exact ties
// from small integer coordinates, and non-finite coordinates (never beyond).
TEST_F(SeparationLanes, SameVerdictsDegenerate) {
  Rng rng("SeparationLanes.SameVerdictsDegenerate", 9303);
  const auto degenerate = [&](int i) {
    const Scalar S = rng.scale(-3, 3);
    const Vec3 a = rng.vec(-S, S), b = rng.vec(-S, S), c = rng.vec(-S, S), d = rng.vec(-S, S);
    constexpr Scalar kNaN = std::numeric_limits<Scalar>::quiet_NaN();
    constexpr Scalar kInf = std::numeric_limits<Scalar>::infinity();
    switch (i % 8) {
      case 0: return Case{a, b, c, c + 2.5 * (b - a)};  // line: parallel segments
      case 1: return Case{a, b, b, a + 3 * (b - a)};    // collinear
      case 2: return Case{a, a, c, d};                  // a point
      case 3: return Case{a, b, c, b + 0.5 * (c - b)};  // plane: degenerate triangle b, c, mid
      case 4:
        return Case{rng.small_integer_point(), rng.small_integer_point(), rng.small_integer_point(),
                    rng.small_integer_point()};
      case 5: return Case{a, b, Vec3(kNaN, c.y(), c.z()), d};
      case 6: return Case{a, Vec3(b.x(), kInf, b.z()), c, d};
      default: return Case{a, b, c, -kInf * d};
    }
  };
  EXPECT_EQ(mismatches<false>(rng, 80000, degenerate), 0);
  EXPECT_EQ(mismatches<true>(rng, 80000, degenerate), 0);
}
#endif

// The scalar test rejects only what is further than the pad: beyond(s, pad) implies that the
// distance exceeds pad, and separation_bound never exceeds the distance, up to the kernel's own
// rounding (1e-12 of the coordinates' magnitude; the detectors' pads exceed the thickness by
// 1e-9 of it, for that rounding). Near-contact cases as above, with pads drawn around the
// separation.
TEST(Separation, RejectsOnlyPairsBeyondThePad) {
  Rng rng("Separation.RejectsOnlyPairsBeyondThePad", 9304);
  int rejected = 0, kept = 0;
  for (int i = 0; i < 200000; ++i) {
    const bool line = i % 2 == 1;
    const Scalar S = rng.scale(-2, 2);
    const Vec3 o = rng.vec(-10 * S, 10 * S);
    const Vec3 n = rng.unit();
    const Scalar gap = S * std::pow(10.0, rng.uniform(-5, 0));
    Case c{o + rng.vec(-S, S), o + rng.vec(-S, S), o + rng.vec(-S, S), o + rng.vec(-S, S)};
    if (rng.coin()) c[line ? 2 : 0] = c[1] + gap * n;  // a feature brought close to the other
    const Separation s = separation(line, c);
    const Scalar d = distance(line, c);
    const Scalar rounding = 1e-12 * test::max_abs_coord({c[0], c[1], c[2], c[3]});
    EXPECT_LE(separation_bound(s), d + rounding) << test::json_case(line ? "line" : "plane", {c[0], c[1], c[2], c[3]});
    const Scalar pad = pad_for(rng, s, S);
    if (beyond(s, pad)) {
      ++rejected;
      EXPECT_GT(d, pad - rounding) << test::json_case(line ? "line" : "plane", {c[0], c[1], c[2], c[3]}) << " pad " << pad;
    } else {
      ++kept;
    }
  }
  // Both verdicts were exercised.
  EXPECT_GT(rejected, 20000);
  EXPECT_GT(kept, 20000);
}

}  // namespace
}  // namespace crumple::geometry
