// The slab test (geometry::ccd_slabs_apart with ccd_hull_bound), the mesh query's certified
// prefilter: it may only reject a pair that ccd's own difference-hull filter rejects (so its
// rejections are certified and the mesh query's impacts equal the narrow phase's on every
// pair), and it must never reject a pair that touches or comes within δ, in particular at its
// boundary (a gap of exactly δ on one axis, contact exactly at t = 0 or t = 1).
#include <crumple/geometry/ccd.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>

namespace crumple::geometry {
namespace {

Scalar magnitude_of(const CcdPoints& s, const CcdPoints& e) {
  Scalar m = 0;
  for (int i = 0; i < 4; ++i) m = std::max({m, s[i].cwiseAbs().maxCoeff(), e[i].cwiseAbs().maxCoeff()});
  return m;
}

/// The slabs of points [first, first + count) of a query.
CcdSlabs slabs(const CcdPoints& s, const CcdPoints& e, int first, int count) {
  CcdSlabs out;
  for (int tau = 0; tau < 2; ++tau) {
    const CcdPoints& x = tau == 0 ? s : e;
    out.lo[tau] = out.hi[tau] = x[first];
    for (int i = first + 1; i < first + count; ++i) {
      out.lo[tau] = out.lo[tau].cwiseMin(x[i]);
      out.hi[tau] = out.hi[tau].cwiseMax(x[i]);
    }
  }
  return out;
}

/// The slab test of a query as the mesh query runs it (its two features, in both orders, must
/// agree), with the bound of magnitude `m` (≥ the query's largest coordinate).
bool slab_rejects(CcdPair pair, const CcdPoints& s, const CcdPoints& e, Scalar delta, Scalar m) {
  const int split = pair == CcdPair::kVertexFace ? 1 : 2;
  const CcdSlabs a = slabs(s, e, 0, split), b = slabs(s, e, split, 4 - split);
  const Scalar bound = ccd_hull_bound(m, delta);
  const bool ab = ccd_slabs_apart(a, b, bound);
  EXPECT_EQ(ab, ccd_slabs_apart(b, a, bound));
  return ab;
}

struct Tally {
  int rejected = 0, kept = 0;
};

/// Checks the subset property on one query: a slab rejection is a hull rejection of ccd.
void check(CcdPair pair, const CcdPoints& s, const CcdPoints& e, Scalar delta, Tally& tally, Scalar extra = 1) {
  const Scalar m = magnitude_of(s, e) * extra;
  CcdOptions o;
  o.min_separation = delta;
  if (slab_rejects(pair, s, e, delta, m)) {
    ++tally.rejected;
    const CcdResult r = ccd(pair, s, e, o);
    EXPECT_FALSE(r.hit);
    EXPECT_EQ(r.outcome, CcdOutcome::kSeparatedHull) << "delta " << delta << " magnitude " << m;
  } else {
    ++tally.kept;
  }
}

TEST(CcdSlabs, RejectOnlyWhatTheHullFilterRejects) {
  // Random pairs at several scales and offsets, one feature shifted along an axis so that the
  // gap straddles the bound: gaps of δ + err × (1 ± 2^-k) and just around δ.
  std::mt19937_64 rng(42);
  std::uniform_real_distribution<Scalar> unit(-1, 1);
  Tally tally;
  int n = 0;
  for (const Scalar scale : {1.0, 0x1p-40, 0x1p40, 1e-300}) {
    for (const Scalar offset : {0.0, 1e6, -3.5}) {
      for (const Scalar delta_rel : {0.0, 1e-3}) {
        for (int trial = 0; trial < 200; ++trial) {
          const CcdPair pair = trial % 2 == 0 ? CcdPair::kVertexFace : CcdPair::kEdgeEdge;
          const int split = pair == CcdPair::kVertexFace ? 1 : 2;
          CcdPoints s, e;
          for (int i = 0; i < 4; ++i) {
            s[i] = scale * Vec3(unit(rng), unit(rng), unit(rng));
            e[i] = s[i] + 0.2 * scale * Vec3(unit(rng), unit(rng), unit(rng));
          }
          const Scalar delta = delta_rel * scale;
          // Place feature b above feature a on axis k at both times with a chosen gap.
          const int k = trial % 3;
          const CcdSlabs a = slabs(s, e, 0, split), b = slabs(s, e, split, 4 - split);
          const Scalar err = ccd_hull_bound(std::abs(offset) + 4 * scale, delta) - delta;
          const Scalar gaps[] = {delta,           delta + err * 0.5,        delta + err * (1 - 0x1p-20),
                                 delta + err,     delta + err * (1 + 0x1p-20), delta + 2 * err,
                                 delta + 0.1 * scale, -delta};
          const Scalar gap = gaps[trial / 2 % 8];
          for (int tau = 0; tau < 2; ++tau) {
            CcdPoints& x = tau == 0 ? s : e;
            const Scalar shift = a.hi[tau][k] - b.lo[tau][k] + gap;  // b.lo = a.hi + gap (rounded)
            for (int i = split; i < 4; ++i) x[i][k] += shift;
          }
          for (int tau = 0; tau < 2; ++tau) {
            CcdPoints& x = tau == 0 ? s : e;
            for (int i = 0; i < 4; ++i) x[i] += Vec3::Constant(offset);
          }
          check(pair, s, e, delta, tally);
          check(pair, s, e, delta, tally, 2);  // a scene bound above the query's
          ++n;
        }
      }
    }
  }
  std::printf("[ ccd slabs ] %d queries: %d slab rejections, %d kept\n", n, tally.rejected, tally.kept);
  // The test exercises both sides of the boundary.
  EXPECT_GT(tally.rejected, n / 4);
  EXPECT_GT(tally.kept, n / 4);
}

TEST(CcdSlabs, NeverRejectATouchingPair) {
  // A vertex resting on an axis-aligned triangle's plane, at a gap of exactly δ, at t = 0 only,
  // at t = 1 only, or crossing it in between: each comes within δ, so the slab test keeps it,
  // whatever the scale and the offset from the origin.
  for (const Scalar scale : {1.0, 0x1p-60, 0x1p60}) {
    for (const Scalar offset : {0.0, 1e5, -7.25}) {
      for (const Scalar delta : {0.0, 0x1p-10 * scale, 0.1 * scale}) {
        const Vec3 o = Vec3::Constant(offset);
        const CcdPoints tri{Vec3::Zero(), o, o + Vec3(scale, 0, 0), o + Vec3(0, scale, 0)};
        const Vec3 at_gap = o + Vec3(0.25 * scale, 0.25 * scale, delta);
        const Vec3 above = o + Vec3(0.25 * scale, 0.25 * scale, delta + scale);
        const Vec3 below = o + Vec3(0.25 * scale, 0.25 * scale, -scale);
        const std::pair<Vec3, Vec3> motions[] = {{at_gap, above}, {above, at_gap}, {above, below}, {at_gap, at_gap}};
        for (const auto& [p0, p1] : motions) {
          CcdPoints s = tri, e = tri;
          s[0] = p0;
          e[0] = p1;
          EXPECT_FALSE(slab_rejects(CcdPair::kVertexFace, s, e, delta, magnitude_of(s, e)))
              << "scale " << scale << " offset " << offset << " delta " << delta;
          CcdOptions opt;
          opt.min_separation = delta;
          EXPECT_TRUE(vertex_face_ccd(s, e, opt).hit);
        }
        // Two edges crossing at a gap of exactly δ along z at t = 1, far apart at t = 0.
        const CcdPoints ea0{o + Vec3(0, 0, 0), o + Vec3(scale, 0, 0), o + Vec3(0.5 * scale, -scale, 2 * scale),
                            o + Vec3(0.5 * scale, scale, 2 * scale)};
        CcdPoints ea1 = ea0;
        ea1[2][2] = ea1[3][2] = offset + delta;
        EXPECT_FALSE(slab_rejects(CcdPair::kEdgeEdge, ea0, ea1, delta, magnitude_of(ea0, ea1)));
        CcdOptions opt;
        opt.min_separation = delta;
        EXPECT_TRUE(edge_edge_ccd(ea0, ea1, opt).hit);
      }
    }
  }
}

TEST(CcdSlabs, ApartOnOneAxisAtOnlyOneTimeIsKept) {
  // The vertex is far above the triangle at t = 0 and far to its side at t = 1, passing beside
  // it: apart on z at t = 0 and on x at t = 1, but on no single axis at both times.
  const CcdPoints tri{Vec3::Zero(), Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0)};
  CcdPoints s = tri, e = tri;
  s[0] = Vec3(0.2, 0.2, 5);
  e[0] = Vec3(5, 0.2, -5);
  EXPECT_FALSE(slab_rejects(CcdPair::kVertexFace, s, e, 0, magnitude_of(s, e)));
  // Far above at both times: rejected.
  e[0] = Vec3(5, 0.2, 4);
  EXPECT_TRUE(slab_rejects(CcdPair::kVertexFace, s, e, 0, magnitude_of(s, e)));
}

TEST(CcdSlabs, HullBoundDominatesEveryQuerysBound) {
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<Scalar> unit(-1, 1);
  for (int trial = 0; trial < 1000; ++trial) {
    const Scalar scale = std::ldexp(1.0, static_cast<int>(rng() % 200) - 100);
    CcdPoints s, e;
    for (int i = 0; i < 4; ++i) {
      s[i] = scale * Vec3(unit(rng), unit(rng), unit(rng));
      e[i] = scale * Vec3(unit(rng), unit(rng), unit(rng));
    }
    const Scalar delta = trial % 2 == 0 ? 0 : scale * 1e-3;
    const Vec3 err = ccd_rounding_bound(s, e);
    const Scalar bound = ccd_hull_bound(magnitude_of(s, e), delta);
    for (int k = 0; k < 3; ++k) EXPECT_GT(bound, err[k] + delta);
  }
  EXPECT_EQ(ccd_hull_bound(0x1p1001, 0), std::numeric_limits<Scalar>::infinity());
  EXPECT_EQ(ccd_hull_bound(std::numeric_limits<Scalar>::quiet_NaN(), 0), std::numeric_limits<Scalar>::infinity());
  EXPECT_EQ(ccd_hull_bound(std::numeric_limits<Scalar>::infinity(), 0), std::numeric_limits<Scalar>::infinity());
}

TEST(CcdSlabs, OutOfRangeIsNeverRejected) {
  // Coordinates above 2^1000 make ccd answer a conservative hit: the slab test keeps them.
  const CcdPoints s{Vec3(0x1p1020, 0, 0), Vec3(-0x1p1020, 0, 0), Vec3(-0x1p1020, 1, 0), Vec3(-0x1p1020, 0, 1)};
  EXPECT_FALSE(slab_rejects(CcdPair::kVertexFace, s, s, 0, magnitude_of(s, s)));
  EXPECT_EQ(vertex_face_ccd(s, s).outcome, CcdOutcome::kHitOutOfRange);
}

}  // namespace
}  // namespace crumple::geometry
