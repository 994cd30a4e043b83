// Narrow-phase CCD (geometry/ccd.hpp) on hand-made cases with known answers: transversal hits,
// touching at t = 0 and t = 1, zero motion, parallel and collinear edges, degenerate
// triangles, tiny and huge scales, the iteration budget and out-of-range input.
#include <crumple/geometry/ccd.hpp>

#include <crumple/core/error.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

namespace crumple::geometry {
namespace {

CcdPoints pts(Vec3 a, Vec3 b, Vec3 c, Vec3 d) { return {a, b, c, d}; }

// Triangle in z = 0 with corners (0,0), (1,0), (0,1), static.
const CcdPoints kTri = pts(Vec3(9, 9, 9), Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0));

CcdResult vf(Vec3 p0, Vec3 p1, const CcdOptions& o = {}) {
  CcdPoints s = kTri, e = kTri;
  s[0] = p0;
  e[0] = p1;
  return vertex_face_ccd(s, e, o);
}

TEST(Ccd, VertexThroughTriangleHitsAtHalfTime) {
  const CcdResult r = vf(Vec3(0.25, 0.25, 1), Vec3(0.25, 0.25, -1));
  ASSERT_TRUE(r.hit);
  EXPECT_LE(r.toi, 0.5);
  EXPECT_GE(r.toi, 0.5 - 2e-6);
  EXPECT_EQ(r.outcome, CcdOutcome::kHitTolerance);
}

TEST(Ccd, FarApartIsRejectedByTheHull) {
  const CcdResult r = vf(Vec3(0.25, 0.25, 1), Vec3(0.25, 0.25, 0.5));
  EXPECT_FALSE(r.hit);
  EXPECT_EQ(r.outcome, CcdOutcome::kSeparatedHull);
  EXPECT_EQ(r.boxes, 0);
}

TEST(Ccd, VertexPassingBesideTheTriangleIsRejected) {
  // Crosses the plane z = 0 at (0.6, 0.6), outside the hypotenuse u + v ≤ 1.
  const CcdResult r = vf(Vec3(0.6, 0.6, 1), Vec3(0.6, 0.6, -1));
  EXPECT_FALSE(r.hit) << to_string(r.outcome);
}

TEST(Ccd, TouchingAtStartAndEnd) {
  const CcdResult start = vf(Vec3(0.2, 0.3, 0), Vec3(0.2, 0.3, 1));
  ASSERT_TRUE(start.hit);
  EXPECT_EQ(start.toi, 0);
  const CcdResult end = vf(Vec3(0.2, 0.3, 1), Vec3(0.2, 0.3, 0));
  ASSERT_TRUE(end.hit);
  EXPECT_LE(end.toi, 1);
  EXPECT_GE(end.toi, 1 - 2e-6);
  // Touching the triangle's corner and edge exactly at t = 1.
  EXPECT_TRUE(vf(Vec3(1, 0, 1), Vec3(1, 0, 0)).hit);
  EXPECT_TRUE(vf(Vec3(0.5, 0.5, 1), Vec3(0.5, 0.5, 0)).hit);
}

TEST(Ccd, ZeroMotion) {
  EXPECT_FALSE(vf(Vec3(0.2, 0.2, 0.1), Vec3(0.2, 0.2, 0.1)).hit);
  const CcdResult on = vf(Vec3(0.2, 0.2, 0), Vec3(0.2, 0.2, 0));
  ASSERT_TRUE(on.hit);
  EXPECT_EQ(on.toi, 0);
  // All eight points identical.
  const CcdPoints same = pts(Vec3(1, 2, 3), Vec3(1, 2, 3), Vec3(1, 2, 3), Vec3(1, 2, 3));
  EXPECT_TRUE(vertex_face_ccd(same, same).hit);
  EXPECT_TRUE(edge_edge_ccd(same, same).hit);
}

TEST(Ccd, EdgesCrossingAtQuarterTime) {
  const CcdPoints s = pts(Vec3(-1, 0, 0), Vec3(1, 0, 0), Vec3(0, -1, 0.25), Vec3(0, 1, 0.25));
  CcdPoints e = s;
  e[2].z() = e[3].z() = -0.75;
  const CcdResult r = edge_edge_ccd(s, e);
  ASSERT_TRUE(r.hit);
  EXPECT_LE(r.toi, 0.25);
  EXPECT_GE(r.toi, 0.25 - 2e-6);
}

TEST(Ccd, ParallelAndCollinearEdges) {
  // Collinear, overlapping, sliding along their line: touching for all t.
  const CcdPoints s = pts(Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0.5, 0, 0), Vec3(1.5, 0, 0));
  CcdPoints e = s;
  e[2].x() += 0.3;
  e[3].x() += 0.3;
  const CcdResult r = edge_edge_ccd(s, e);
  ASSERT_TRUE(r.hit);
  EXPECT_EQ(r.toi, 0);
  // Collinear, approaching end to end: touch when the gap 0.5 closes at t = 0.5.
  const CcdPoints s2 = pts(Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(1.5, 0, 0), Vec3(2.5, 0, 0));
  CcdPoints e2 = s2;
  e2[2].x() -= 1;
  e2[3].x() -= 1;
  const CcdResult r2 = edge_edge_ccd(s2, e2);
  ASSERT_TRUE(r2.hit);
  EXPECT_LE(r2.toi, 0.5);
  EXPECT_GE(r2.toi, 0.5 - 2e-6);
  // Parallel at distance 0.1 sliding over each other: no contact.
  CcdPoints s3 = s, e3 = e;
  for (int i = 2; i < 4; ++i) {
    s3[i].y() = 0.1;
    e3[i].y() = 0.1;
  }
  EXPECT_FALSE(edge_edge_ccd(s3, e3).hit);
  // ... but within δ = 0.15.
  CcdOptions o;
  o.min_separation = 0.15;
  EXPECT_TRUE(edge_edge_ccd(s3, e3, o).hit);
}

TEST(Ccd, DegenerateTriangles) {
  // Triangle collapsed to a segment from (0,0,0) to (1,0,0); vertex crosses it at x = 0.5.
  CcdPoints s = pts(Vec3(0.5, 0, 1), Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0.5, 0, 0));
  CcdPoints e = s;
  e[0] = Vec3(0.5, 0, -1);
  EXPECT_TRUE(vertex_face_ccd(s, e).hit);
  // Collapsed to a point at the origin; vertex through it, and beside it.
  s = pts(Vec3(0, 0, 1), Vec3(0, 0, 0), Vec3(0, 0, 0), Vec3(0, 0, 0));
  e = s;
  e[0] = Vec3(0, 0, -1);
  EXPECT_TRUE(vertex_face_ccd(s, e).hit);
  s[0].x() = e[0].x() = 0.01;
  EXPECT_FALSE(vertex_face_ccd(s, e).hit);
  // Zero-length edge (a point) through a segment.
  const CcdPoints es = pts(Vec3(0.5, 1, 0), Vec3(0.5, 1, 0), Vec3(0, 0, 0), Vec3(1, 0, 0));
  CcdPoints ee = es;
  ee[0].y() = ee[1].y() = -1;
  EXPECT_TRUE(edge_edge_ccd(es, ee).hit);
}

TEST(Ccd, TinyAndHugeScales) {
  // Past 2^300 (1e200, 1e300) the sign filter and advancement are off, and squared lengths
  // overflowed: inf <= inf made every bisection corner a witness (the miss was a hit at t = 0).
  for (const Scalar scale : {1e-200, 1e-20, 3e-15, 1.0, 7e8, 1e20, 1e200, 1e300}) {
    CcdPoints s = kTri, e = kTri;
    s[0] = Vec3(0.25, 0.25, 1);
    e[0] = Vec3(0.25, 0.25, -1);
    CcdPoints miss_s = s, miss_e = e;
    miss_s[0].x() = miss_e[0].x() = 0.8;  // outside u + v ≤ 1
    for (int i = 0; i < 4; ++i) {
      for (CcdPoints* x : {&s, &e, &miss_s, &miss_e}) (*x)[i] = ((*x)[i] * scale).eval();
    }
    const CcdResult r = vertex_face_ccd(s, e);
    ASSERT_TRUE(r.hit) << scale << " " << to_string(r.outcome);
    EXPECT_LE(r.toi, 0.5) << scale;
    EXPECT_GE(r.toi, 0.5 - 2e-6) << scale << " " << to_string(r.outcome);
    EXPECT_FALSE(vertex_face_ccd(miss_s, miss_e).hit) << scale;
  }
}

// Two edges about 0.1 apart all step (from a crumpled lattice: the pair that made `kdop`
// differ from brute force at 1e200): apart at every scale up to the narrow phase's range.
TEST(Ccd, EdgesApartAtEveryScale) {
  const CcdPoints s0 = pts(Vec3(0.782409, 0.550568, 0.0112717), Vec3(1.06189, 0.616255, 0.0418252),
                           Vec3(0.684851, 0.769551, -0.0147011), Vec3(0.69007, 0.943782, 0.00950558));
  const CcdPoints e0 = pts(Vec3(0.732154, 0.46771, 0.0645032), Vec3(0.895191, 0.882173, 0.0940357),
                           Vec3(0.700666, 0.870223, 0.156244), Vec3(0.758529, 1.13695, 0.0169541));
  for (const Scalar scale : {1e-200, 1e-40, 1.0, 1e39, 1e100, 1e200, 1e300}) {
    CcdPoints s = s0, e = e0;
    for (int i = 0; i < 4; ++i) {
      s[i] *= scale;
      e[i] *= scale;
    }
    EXPECT_FALSE(edge_edge_ccd(s, e).hit) << scale;
    CcdOptions o;
    o.min_separation = 0.01 * scale;
    EXPECT_FALSE(edge_edge_ccd(s, e, o).hit) << scale;
  }
}

TEST(Ccd, MinimumSeparation) {
  CcdOptions o;
  o.min_separation = 0.1;
  // Passes 0.05 above the triangle: within δ from when it is 0.1 above the interior.
  const CcdResult near = vf(Vec3(0.25, 0.25, 1.05), Vec3(0.25, 0.25, 0.05), o);
  ASSERT_TRUE(near.hit);
  EXPECT_LE(near.toi, 0.95);
  EXPECT_GE(near.toi, 0.95 - 1e-3);
  // Stays 0.3 above: L∞ inflation reaches at most √3 δ < 0.3, so this must be rejected.
  EXPECT_FALSE(vf(Vec3(0.25, 0.25, 1.3), Vec3(0.25, 0.25, 0.3), o).hit);
  // Already within δ at t = 0.
  const CcdResult start = vf(Vec3(0.25, 0.25, 0.09), Vec3(0.25, 0.25, 1), o);
  ASSERT_TRUE(start.hit);
  EXPECT_EQ(start.toi, 0);
}

TEST(Ccd, CoplanarityFilterRejectsSkewMotion) {
  // Skew edges whose boxes (and difference hull) overlap on every axis but whose lines stay
  // at a distance: the 4 points are never coplanar.
  const CcdPoints s = pts(Vec3(0, 0, -1), Vec3(1, 1, 1), Vec3(1, 0, 1.5), Vec3(0, 1, -0.5));
  CcdPoints e = s;
  e[2].z() += 0.1;
  e[3].z() += 0.1;
  const CcdResult r = edge_edge_ccd(s, e);
  EXPECT_FALSE(r.hit);
  EXPECT_EQ(r.outcome, CcdOutcome::kSeparatedCoplanarity);
}

TEST(Ccd, NearParallelEdgesAreSeparatedByADirection) {
  // cloth-funnel 227->228: two nearly parallel edges about 1e-6 apart (the scene is ~1 wide).
  // Bisection alone spent its whole budget (100000 boxes) on this pair.
  const CcdPoints s = pts(Vec3(0x1.0ed1cp-6, -0x1.b89f84p-5, -0x1.3071c6p-1), Vec3(0x1.6475ccp-6, -0x1.a73e9ep-5, -0x1.315076p-1),
                          Vec3(0x1.0ed65cp-6, -0x1.b89f84p-5, -0x1.30714p-1), Vec3(0x1.647baap-6, -0x1.a73e9ep-5, -0x1.314fcep-1));
  const CcdPoints e = pts(Vec3(0x1.0f677cp-6, -0x1.b989c4p-5, -0x1.320276p-1), Vec3(0x1.653a82p-6, -0x1.a81fa4p-5, -0x1.32e16ap-1),
                          Vec3(0x1.0f60c6p-6, -0x1.b989c4p-5, -0x1.3202fcp-1), Vec3(0x1.65321ep-6, -0x1.a81fa4p-5, -0x1.32e232p-1));
  const CcdResult r = edge_edge_ccd(s, e);
  EXPECT_NE(r.outcome, CcdOutcome::kHitBudget);
  EXPECT_LT(r.boxes, 1000);
}

TEST(Ccd, BudgetGivesAConservativeHit) {
  CcdOptions o;
  o.max_boxes = 1;
  o.max_advance_steps = 0;  // bisection alone
  const CcdResult r = vf(Vec3(0.25, 0.25, 1), Vec3(0.25, 0.25, -1), o);
  ASSERT_TRUE(r.hit);
  EXPECT_EQ(r.outcome, CcdOutcome::kHitBudget);
  EXPECT_LE(r.toi, 0.5);
  EXPECT_EQ(r.boxes, 1);
}

TEST(Ccd, AdvancementFindsTranslationalContactsWithoutBisection) {
  // A pure translation towards the triangle: the closest-point direction's bound is exact, so
  // one step lands on the contact and the next finds the witness.
  const CcdResult r = vf(Vec3(0.25, 0.25, 1), Vec3(0.25, 0.25, -1));
  ASSERT_TRUE(r.hit);
  EXPECT_EQ(r.outcome, CcdOutcome::kHitTolerance);
  EXPECT_EQ(r.boxes, 0);
  EXPECT_LE(r.advance_steps, 2);
  EXPECT_LE(r.toi, 0.5);
  EXPECT_GE(r.toi, 0.5 - 1e-9);
}

TEST(Ccd, ApartAtTheStartButWithinTheToleranceGetsAPositiveTime) {
  // 1e-9 above the triangle: within the distance tolerance (1e-6 × extent) at t = 0, but apart.
  // Moving away: no contact at all (it used to be a near-contact hit at t = 0).
  const CcdResult away = vf(Vec3(0.25, 0.25, 1e-9), Vec3(0.25, 0.25, 1));
  EXPECT_FALSE(away.hit) << to_string(away.outcome);
  // Moving through: the TOI is positive and not after the contact at 1e-9 / (1 + 1e-9).
  const CcdResult through = vf(Vec3(0.25, 0.25, 1e-9), Vec3(0.25, 0.25, -1));
  ASSERT_TRUE(through.hit);
  EXPECT_GT(through.toi, 0);
  EXPECT_LE(through.toi, 1e-9 / (1 + 1e-9));
  // Touching at t = 0 stays a hit at 0.
  EXPECT_EQ(vf(Vec3(0.25, 0.25, 0), Vec3(0.25, 0.25, 1)).toi, 0);
}

TEST(Ccd, NonFiniteOrHugeInputIsAConservativeHit) {
  const Scalar nan = std::numeric_limits<Scalar>::quiet_NaN();
  const CcdResult r = vf(Vec3(nan, 0, 0), Vec3(0, 0, 0));
  EXPECT_TRUE(r.hit);
  EXPECT_EQ(r.outcome, CcdOutcome::kHitOutOfRange);
  EXPECT_EQ(r.toi, 0);
  EXPECT_EQ(vf(Vec3(1e306, 0, 0), Vec3(0, 0, 0)).outcome, CcdOutcome::kHitOutOfRange);
  CcdOptions o;
  o.min_separation = -1;
  EXPECT_THROW(vf(Vec3(0, 0, 1), Vec3(0, 0, 1), o), PreconditionError);
}

TEST(Ccd, RoundingBoundScalesWithCoordinates) {
  const CcdPoints s = pts(Vec3(1, -2, 0), Vec3(0, 0, 0), Vec3(0, 0, 0), Vec3(0, 0, 4));
  const Vec3 err = ccd_rounding_bound(s, s);
  EXPECT_EQ(err.x(), 64 * 0x1p-53 + 0x1p-1000);
  EXPECT_EQ(err.y(), 128 * 0x1p-53 + 0x1p-1000);
  EXPECT_EQ(err.z(), 256 * 0x1p-53 + 0x1p-1000);
}

}  // namespace
}  // namespace crumple::geometry
