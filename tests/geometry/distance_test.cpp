/// Distance kernels against independent higher-precision oracles (distance_oracle.hpp) and
/// against their invariants (symmetry, rigid-motion invariance, self-consistency of the
/// returned parameters, closest points, barycentrics and regions).
///
/// Tolerances. Every kernel works in a frame local to one input point, so the only
/// unavoidable error is the rounding of the input differences, ~eps*L with eps = 2^-53 and
/// L = the largest |coordinate| of the case (scale *and* distance from the origin). A
/// backward-stable kernel returns the exact distance of inputs moved by a few eps*L, and the
/// distance between sets is 1-Lipschitz under moving their points, so its distance error is
/// O(eps*L) whatever the conditioning of the closest *points* (near-parallel segments,
/// slivers). We allow kTolUlps = 64 eps*L (~7e-15 L); the largest error observed, printed by
/// each test in units of eps*L, is below 8 (the margin covers other seeds and compilers).
/// Parameters, barycentrics and closest points are checked through the distances they
/// reproduce, with the same tolerance: they are ill-conditioned (parallel segments have a
/// continuum of closest pairs; a sliver's barycentrics are undetermined across its width).

#include <crumple/geometry/distance.hpp>

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstdio>
#include <functional>
#include <numbers>
#include <string>
#include <vector>

#include "distance_oracle.hpp"
#include "geometry_test_support.hpp"

namespace crumple::geometry {
namespace {

using test::json_case;
using test::kEps;
using test::max_abs_coord;
using test::Rng;

constexpr Scalar kTolUlps = 64;

/// Collects failures (reporting the first few with their input as JSON) and the worst
/// error in units of eps*L.
class Checker {
 public:
  explicit Checker(std::string name) : name_(std::move(name)) {}
  ~Checker() {
    std::printf("[ accuracy ] %-40s %8ld cases, max error %.3g eps*L\n", name_.c_str(), cases_,
                worst_);
  }
  void count() { ++cases_; }
  /// Records |got - want| <= tol_ulps * eps * L.
  void close(const char* what, Scalar got, Scalar want, Scalar L, Scalar tol_ulps,
             const std::string& input) {
    const Scalar err = std::abs(got - want) / (kEps * std::max(L, Scalar(1e-300)));
    if (what[0] == 'd') worst_ = std::max(worst_, err);
    if (!(err <= tol_ulps)) fail(std::string(what) + ": got " + fmt(got) + ", want " + fmt(want) +
                                 " (error " + fmt(err) + " eps*L)", input);
  }
  void check(bool ok, const std::string& what, const std::string& input) {
    if (!ok) fail(what, input);
  }
  long failures() const { return failures_; }

 private:
  static std::string fmt(Scalar x) {
    char buf[40];
    std::snprintf(buf, sizeof buf, "%.17g", x);
    return buf;
  }
  void fail(const std::string& what, const std::string& input) {
    if (++failures_ <= 8) ADD_FAILURE() << name_ << ": " << what << "\n  input: " << input;
  }
  std::string name_;
  long cases_ = 0;
  long failures_ = 0;
  Scalar worst_ = 0;
};

// ------------------------------------------------------------------------------------------
// Point - segment
// ------------------------------------------------------------------------------------------

void check_point_segment(Checker& ck, const Vec3& p, const Vec3& a, const Vec3& b,
                         Scalar tol_ulps = kTolUlps) {
  ck.count();
  const PointSegmentResult r = point_segment(p, a, b);
  const std::string in = json_case("point_segment", {p, a, b});
  const Scalar L = max_abs_coord({p, a, b});
  const Scalar want = std::sqrt(static_cast<Scalar>(test::oracle_point_segment(p, a, b)));
  ck.close("distance", std::sqrt(r.sqr_distance), want, L, tol_ulps, in);
  ck.check(r.t >= 0 && r.t <= 1, "t outside [0,1]", in);
  ck.close("|closest - p|", (r.closest - p).norm(), std::sqrt(r.sqr_distance), L, tol_ulps, in);
  ck.close("closest = a + t(b-a)", (r.closest - (a + r.t * (b - a))).norm(), 0, L, tol_ulps, in);
  if (a == b) ck.check(r.t == 0 && r.closest == a, "zero-length segment must give t = 0", in);
}

TEST(PointSegment, MatchesOracle) {
  Rng rng("PointSegment.MatchesOracle", 20240601);
  Checker generic("point_segment generic"), degenerate("point_segment degenerate"),
      on_line("point_segment on/near the line");
  for (int i = 0; i < 60000; ++i) {
    const Scalar S = rng.scale(-3, 3);
    const Vec3 o = rng.coin() ? Vec3::Zero() : rng.vec(-10 * S, 10 * S);
    check_point_segment(generic, o + rng.vec(-S, S), o + rng.vec(-S, S), o + rng.vec(-S, S));
  }
  for (int i = 0; i < 20000; ++i) {
    const Scalar S = rng.scale(-3, 3);
    const Vec3 o = rng.vec(-5 * S, 5 * S);
    const Vec3 a = o + rng.vec(-S, S);
    switch (i % 4) {
      case 0: check_point_segment(degenerate, o + rng.vec(-S, S), a, a); break;  // zero length
      case 1: check_point_segment(degenerate, a, a, a); break;                   // all coincide
      case 2: check_point_segment(degenerate, a, a, o + rng.vec(-S, S)); break;  // p = a
      default: {
        const Vec3 b = o + rng.vec(-S, S);
        check_point_segment(degenerate, b, a, b);  // p = b
      }
    }
  }
  for (int i = 0; i < 40000; ++i) {
    // On the line, inside or beyond the ends, at tiny distances from it.
    const Scalar S = rng.scale(-3, 3);
    const Vec3 o = rng.vec(-5 * S, 5 * S);
    const Vec3 a = o + rng.vec(-S, S), b = o + rng.vec(-S, S);
    const Scalar lambda = rng.uniform(-0.5, 1.5);
    const Vec3 n = rng.orthogonal_unit((b - a).normalized());
    const Scalar off = (i % 3 == 0) ? 0 : S * std::pow(10.0, -rng.integer(1, 15));
    check_point_segment(on_line, a + lambda * (b - a) + off * n, a, b);
  }
  EXPECT_EQ(generic.failures() + degenerate.failures() + on_line.failures(), 0);
}

// ------------------------------------------------------------------------------------------
// Segment - segment
// ------------------------------------------------------------------------------------------

struct Seg2 {
  Vec3 p0, p1, q0, q1;
};

void check_segment_segment(Checker& ck, const Seg2& c, Scalar tol_ulps = kTolUlps) {
  ck.count();
  const auto& [p0, p1, q0, q1] = c;
  const SegmentSegmentResult r = segment_segment(p0, p1, q0, q1);
  const std::string in = json_case("segment_segment", {p0, p1, q0, q1});
  const Scalar L = max_abs_coord({p0, p1, q0, q1});
  const Scalar want =
      std::sqrt(static_cast<Scalar>(test::oracle_segment_segment(p0, p1, q0, q1)));
  const Scalar got = std::sqrt(r.sqr_distance);
  ck.close("distance", got, want, L, tol_ulps, in);
  ck.check(r.s >= 0 && r.s <= 1 && r.t >= 0 && r.t <= 1, "parameters outside [0,1]", in);
  ck.close("|closest0 - closest1|", (r.closest0 - r.closest1).norm(), got, L, tol_ulps, in);
  ck.close("closest0 = P(s)", (r.closest0 - (p0 + r.s * (p1 - p0))).norm(), 0, L, tol_ulps, in);
  ck.close("closest1 = Q(t)", (r.closest1 - (q0 + r.t * (q1 - q0))).norm(), 0, L, tol_ulps, in);
  // Symmetry: swapping the segments or reversing either gives the same distance.
  ck.close("d(Q,P)", std::sqrt(segment_segment(q0, q1, p0, p1).sqr_distance), got, L,
           tol_ulps, in);
  ck.close("d(P reversed,Q)", std::sqrt(segment_segment(p1, p0, q0, q1).sqr_distance), got, L,
           tol_ulps, in);
  // Deterministic: bit-identical on a second call.
  const SegmentSegmentResult again = segment_segment(p0, p1, q0, q1);
  ck.check(again.s == r.s && again.t == r.t && again.sqr_distance == r.sqr_distance,
           "not deterministic", in);
}

TEST(SegmentSegment, MatchesOracleGeneric) {
  Rng rng("SegmentSegment.MatchesOracleGeneric", 7001);
  Checker ck("segment_segment generic");
  for (int i = 0; i < 50000; ++i) {
    const Scalar S = rng.scale(-3, 3);
    const Vec3 o = rng.coin() ? Vec3::Zero() : rng.vec(-10 * S, 10 * S);
    // Mixed lengths: short segments against long ones exercise all 9 regions of (s,t).
    const Scalar l1 = rng.coin() ? 1.0 : 0.05, l2 = rng.coin() ? 1.0 : 0.05;
    const Vec3 p0 = o + rng.vec(-S, S), q0 = o + rng.vec(-S, S);
    check_segment_segment(ck, {p0, p0 + l1 * rng.vec(-S, S), q0, q0 + l2 * rng.vec(-S, S)});
  }
  EXPECT_EQ(ck.failures(), 0);
}

TEST(SegmentSegment, MatchesOracleDegenerate) {
  Rng rng("SegmentSegment.MatchesOracleDegenerate", 7002);
  Checker ck("segment_segment degenerate");
  for (int i = 0; i < 25000; ++i) {
    const Scalar S = rng.scale(-3, 3);
    const Vec3 o = rng.vec(-5 * S, 5 * S);
    const Vec3 a = o + rng.vec(-S, S), b = o + rng.vec(-S, S), c = o + rng.vec(-S, S),
               d = o + rng.vec(-S, S);
    switch (i % 8) {
      case 0: check_segment_segment(ck, {a, a, c, d}); break;  // P is a point
      case 1: check_segment_segment(ck, {a, b, c, c}); break;  // Q is a point
      case 2: check_segment_segment(ck, {a, a, c, c}); break;  // both points
      case 3: check_segment_segment(ck, {a, a, a, a}); break;  // all coincide
      case 4: check_segment_segment(ck, {a, b, a, d}); break;  // shared start
      case 5: check_segment_segment(ck, {a, b, c, b}); break;  // shared end
      case 6: check_segment_segment(ck, {a, b, b, a}); break;  // same segment, reversed
      default: {
        // Crossing (distance ~0): Q passes through a point of P.
        const Vec3 x = a + rng.uniform(0, 1) * (b - a);
        const Vec3 dir = c - d;
        const Scalar mu = rng.uniform(0, 1);
        check_segment_segment(ck, {a, b, x - mu * dir, x + (1 - mu) * dir});
      }
    }
  }
  EXPECT_EQ(ck.failures(), 0);
}

TEST(SegmentSegment, MatchesOracleNearParallel) {
  Rng rng("SegmentSegment.MatchesOracleNearParallel", 7003);
  Checker ck("segment_segment near-parallel");
  const std::array<Scalar, 7> angles{1e-4, 1e-6, 1e-8, 1e-10, 1e-12, 0.0, 1e-14};
  for (int i = 0; i < 42000; ++i) {
    const Scalar theta = angles[i % angles.size()];
    const Scalar S = rng.scale(-3, 3);
    const Vec3 o = rng.coin() ? Vec3::Zero() : rng.vec(-10 * S, 10 * S);
    const Vec3 d = rng.unit();
    const Vec3 m = rng.orthogonal_unit(d);
    const Vec3 n = rng.orthogonal_unit(d);
    // Direction of Q: d rotated by theta, possibly anti-parallel.
    Vec3 d2 = std::cos(theta) * d + std::sin(theta) * m;
    if (rng.coin()) d2 = -d2;
    const Scalar l1 = S * rng.uniform(0.1, 1), l2 = S * rng.uniform(0.1, 1);
    const Vec3 p0 = o + rng.vec(-S, S);
    // Start of Q along P: overlapping, touching-ish or disjoint along the common direction.
    const Scalar along = l1 * rng.uniform(-1.5, 1.5);
    const int k = rng.integer(0, 16);
    const Scalar sep = (k == 16) ? 0.0 : S * std::pow(10.0, -k);  // 0: collinear
    const Vec3 q0 = p0 + along * d + sep * n;
    check_segment_segment(ck, {p0, p0 + l1 * d, q0, q0 + l2 * d2});
  }
  EXPECT_EQ(ck.failures(), 0);
}

TEST(SegmentSegment, ParallelOverlappingIsDeterministicAndExact) {
  // Exactly parallel, overlapping segments on integer coordinates: distance exactly 1.
  const SegmentSegmentResult r =
      segment_segment(Vec3(0, 0, 0), Vec3(4, 0, 0), Vec3(1, 1, 0), Vec3(6, 1, 0));
  EXPECT_EQ(r.sqr_distance, 1.0);
  EXPECT_EQ(r.closest0.y(), 0.0);
  EXPECT_EQ(r.closest1.y(), 1.0);
  EXPECT_GE(r.closest0.x(), 1.0);
  EXPECT_LE(r.closest0.x(), 4.0);
  EXPECT_DOUBLE_EQ(r.closest0.x(), r.closest1.x());
  // Collinear overlapping: distance 0.
  EXPECT_EQ(segment_segment(Vec3(0, 0, 0), Vec3(4, 0, 0), Vec3(5, 0, 0), Vec3(2, 0, 0))
                .sqr_distance,
            0.0);
  // Collinear disjoint: gap 1 between the ends 4 and 5.
  const SegmentSegmentResult g =
      segment_segment(Vec3(0, 0, 0), Vec3(4, 0, 0), Vec3(5, 0, 0), Vec3(9, 0, 0));
  EXPECT_EQ(g.sqr_distance, 1.0);
  EXPECT_EQ(g.s, 1.0);
  EXPECT_EQ(g.t, 0.0);
}

TEST(SegmentSegment, RigidMotionInvariance) {
  Rng rng("SegmentSegment.RigidMotionInvariance", 7004);
  Checker ck("segment_segment rigid motion");
  for (int i = 0; i < 20000; ++i) {
    const Scalar S = rng.scale(-2, 2);
    Seg2 c{rng.vec(-S, S), rng.vec(-S, S), rng.vec(-S, S), rng.vec(-S, S)};
    if (i % 4 == 1) c.q1 = c.q0 + (c.p1 - c.p0) * 0.7 + rng.vec(-1e-9 * S, 1e-9 * S);
    if (i % 4 == 2) c.q1 = c.q0;
    const Eigen::Matrix3d R = rng.rotation();
    const Vec3 T = rng.vec(-10 * S, 10 * S);
    const Seg2 m{R * c.p0 + T, R * c.p1 + T, R * c.q0 + T, R * c.q1 + T};
    const Scalar L = max_abs_coord({c.p0, c.p1, c.q0, c.q1, m.p0, m.p1, m.q0, m.q1});
    ck.count();
    // Rotating a point costs ~3 eps*|p| itself, hence the allowance doubled.
    ck.close("distance", std::sqrt(segment_segment(m.p0, m.p1, m.q0, m.q1).sqr_distance),
             std::sqrt(segment_segment(c.p0, c.p1, c.q0, c.q1).sqr_distance), L, 2 * kTolUlps,
             json_case("segment_segment", {c.p0, c.p1, c.q0, c.q1}));
  }
  EXPECT_EQ(ck.failures(), 0);
}

// ------------------------------------------------------------------------------------------
// Point - triangle
// ------------------------------------------------------------------------------------------

struct Tri {
  Vec3 p, a, b, c;
};

void check_point_triangle(Checker& ck, const Tri& c, Scalar tol_ulps = kTolUlps) {
  ck.count();
  const auto& [p, a, b, t] = c;
  const PointTriangleResult r = point_triangle(p, a, b, t);
  const std::string in = json_case("point_triangle", {p, a, b, t});
  const Scalar L = max_abs_coord({p, a, b, t});
  const Scalar want = std::sqrt(static_cast<Scalar>(test::oracle_point_triangle(p, a, b, t)));
  const Scalar got = std::sqrt(r.sqr_distance);
  ck.close("distance", got, want, L, tol_ulps, in);
  const Vec3& w = r.barycentric;
  ck.check(w.minCoeff() >= 0, "negative barycentric", in);
  ck.check(std::abs(w.sum() - 1) <= 4 * kEps, "barycentrics do not sum to 1", in);
  ck.close("|closest - p|", (r.closest - p).norm(), got, L, tol_ulps, in);
  ck.close("closest = sum w_i v_i", (r.closest - (w[0] * a + w[1] * b + w[2] * t)).norm(), 0, L,
           tol_ulps, in);
  // The region names exactly the features with non-zero weight.
  const bool z0 = w[0] == 0, z1 = w[1] == 0, z2 = w[2] == 0;
  bool region_ok = false;
  switch (r.region) {
    case TriangleRegion::Face: region_ok = !z0 && !z1 && !z2; break;
    case TriangleRegion::EdgeAB: region_ok = !z0 && !z1 && z2; break;
    case TriangleRegion::EdgeBC: region_ok = z0 && !z1 && !z2; break;
    case TriangleRegion::EdgeCA: region_ok = !z0 && z1 && !z2; break;
    case TriangleRegion::VertexA: region_ok = z1 && z2 && r.closest == a; break;
    case TriangleRegion::VertexB: region_ok = z0 && z2 && r.closest == b; break;
    case TriangleRegion::VertexC: region_ok = z0 && z1 && r.closest == t; break;
  }
  ck.check(region_ok, "region disagrees with barycentrics", in);
  // Corner order does not matter: cyclic shift and reflection.
  ck.close("d(p; b,c,a)", std::sqrt(point_triangle(p, b, t, a).sqr_distance), got, L, tol_ulps,
           in);
  ck.close("d(p; a,c,b)", std::sqrt(point_triangle(p, a, t, b).sqr_distance), got, L, tol_ulps,
           in);
}

TEST(PointTriangle, MatchesOracleGeneric) {
  Rng rng("PointTriangle.MatchesOracleGeneric", 9001);
  Checker ck("point_triangle generic");
  for (int i = 0; i < 50000; ++i) {
    const Scalar S = rng.scale(-3, 3);
    const Vec3 o = rng.coin() ? Vec3::Zero() : rng.vec(-10 * S, 10 * S);
    const Vec3 a = o + rng.vec(-S, S), b = o + rng.vec(-S, S), c = o + rng.vec(-S, S);
    Vec3 p = o + rng.vec(-2 * S, 2 * S);
    if (i % 5 == 0) {
      // On or just off the triangle (distance 0 up to rounding, or tiny).
      Scalar u = rng.uniform(0, 1), v = rng.uniform(0, 1);
      if (u + v > 1) u = 1 - u, v = 1 - v;
      const Vec3 n = (b - a).cross(c - a).normalized();
      p = a + u * (b - a) + v * (c - a) + ((i % 10 == 0) ? 0.0 : S * 1e-9) * n;
    } else if (i % 5 == 1) {
      // In the plane of the triangle, outside it.
      p = a + rng.uniform(-2, 2) * (b - a) + rng.uniform(-2, 2) * (c - a);
    }
    check_point_triangle(ck, {p, a, b, c});
  }
  EXPECT_EQ(ck.failures(), 0);
}

TEST(PointTriangle, VoronoiRegions) {
  // A point placed (with a margin) in the Voronoi region of a feature has that feature as
  // its exact answer: closest point known in closed form, region known exactly.
  Rng rng("PointTriangle.VoronoiRegions", 9002);
  Checker ck("point_triangle voronoi regions");
  for (int i = 0; i < 21000; ++i) {
    const Scalar S = rng.scale(-2, 2);
    const Vec3 o = rng.coin() ? Vec3::Zero() : rng.vec(-10 * S, 10 * S);
    Vec3 v[3] = {o + rng.vec(-S, S), o + rng.vec(-S, S), o + rng.vec(-S, S)};
    // Want a well-shaped triangle: every angle below 150 degrees (so that each corner's
    // normal cone has room for the margin below) and a clear normal.
    bool well_shaped = true;
    for (int k = 0; k < 3; ++k) {
      const Vec3 e1 = (v[(k + 1) % 3] - v[k]).normalized(), e2 = (v[(k + 2) % 3] - v[k]).normalized();
      well_shaped = well_shaped && e1.dot(e2) > -0.85 && e1.cross(e2).norm() > 0.05;
    }
    if (!well_shaped) continue;
    const Vec3 n = (v[1] - v[0]).cross(v[2] - v[0]).normalized();
    const Scalar h = rng.uniform(-S, S);  // height above the plane
    const int feature = i % 7;            // 0 face, 1..3 edges ab, bc, ca, 4..6 vertices
    Vec3 p, expected_closest;
    TriangleRegion expected;
    if (feature == 0) {
      Scalar u, w;
      do {
        u = rng.uniform(0.05, 0.9), w = rng.uniform(0.05, 0.9);
      } while (u + w > 0.95);
      expected_closest = v[0] + u * (v[1] - v[0]) + w * (v[2] - v[0]);
      p = expected_closest + h * n;
      expected = TriangleRegion::Face;
    } else if (feature <= 3) {
      const int e = feature - 1;
      const Vec3 &x0 = v[e], &x1 = v[(e + 1) % 3], &opp = v[(e + 2) % 3];
      const Vec3 dir = (x1 - x0).normalized();
      Vec3 out = n.cross(dir);
      if (out.dot(opp - x0) > 0) out = -out;  // outward in-plane normal of the side
      expected_closest = x0 + rng.uniform(0.05, 0.95) * (x1 - x0);
      p = expected_closest + rng.uniform(0.01, 1) * S * out + h * n;
      expected = std::array{TriangleRegion::EdgeAB, TriangleRegion::EdgeBC,
                            TriangleRegion::EdgeCA}[e];
    } else {
      const int k = feature - 4;
      const Vec3 e1 = (v[(k + 1) % 3] - v[k]).normalized(), e2 = (v[(k + 2) % 3] - v[k]).normalized();
      Vec3 dir;
      do {  // normal cone of the corner, with a margin
        dir = rng.unit();
      } while (!(dir.dot(e1) < -0.05 && dir.dot(e2) < -0.05));
      expected_closest = v[k];
      p = v[k] + rng.uniform(0.01, 2) * S * dir;
      expected = std::array{TriangleRegion::VertexA, TriangleRegion::VertexB,
                            TriangleRegion::VertexC}[k];
    }
    check_point_triangle(ck, {p, v[0], v[1], v[2]});
    const PointTriangleResult r = point_triangle(p, v[0], v[1], v[2]);
    const std::string in = json_case("point_triangle", {p, v[0], v[1], v[2]});
    ck.check(r.region == expected, "wrong region", in);
    ck.close("closest point", (r.closest - expected_closest).norm(), 0,
             max_abs_coord({p, v[0], v[1], v[2]}), 4 * kTolUlps, in);
  }
  EXPECT_EQ(ck.failures(), 0);
}

TEST(PointTriangle, MatchesOracleDegenerate) {
  Rng rng("PointTriangle.MatchesOracleDegenerate", 9003);
  Checker ck("point_triangle degenerate");
  for (int i = 0; i < 30000; ++i) {
    const Scalar S = rng.scale(-3, 3);
    const Vec3 o = rng.vec(-5 * S, 5 * S);
    const Vec3 a = o + rng.vec(-S, S), b = o + rng.vec(-S, S);
    Vec3 c;
    switch (i % 6) {
      case 0: c = a + rng.uniform(-0.5, 1.5) * (b - a); break;  // collinear (rounded)
      case 1: c = a; break;                                     // c coincides with a
      case 2: c = b; break;                                     // c coincides with b
      case 3: {                                                 // exactly collinear, integers
        const Vec3 ai = a.array().round().matrix(), di = (b - a).array().round().matrix();
        check_point_triangle(ck, {o.array().round().matrix() + rng.vec(-S, S), ai, ai + di,
                                  ai + Scalar(rng.integer(-2, 3)) * di});
        continue;
      }
      case 4: {  // all three coincide
        check_point_triangle(ck, {o + rng.vec(-S, S), a, a, a});
        continue;
      }
      default: c = b + rng.uniform(0, 1) * (a - b); break;  // c inside side ab
    }
    Vec3 p = o + rng.vec(-S, S);
    if (rng.coin()) p = a + rng.uniform(-0.2, 1.2) * (b - a) + rng.vec(-1e-6 * S, 1e-6 * S);
    check_point_triangle(ck, {p, a, b, c});
  }
  EXPECT_EQ(ck.failures(), 0);
}

TEST(PointTriangle, MatchesOracleSlivers) {
  // c = a + lambda (b - a) + width * m: height over ab from 1e-2 down to 1e-14 of |ab|, the
  // regime where the normal equations of the classic algorithm lose eps/sin^2(angle) and
  // used to misclassify regions. Points anywhere, on the sliver, or in its plane near it.
  Rng rng("PointTriangle.MatchesOracleSlivers", 9004);
  Checker ck("point_triangle slivers");
  for (int i = 0; i < 30000; ++i) {
    const Scalar S = rng.scale(-2, 2);
    const Vec3 o = rng.coin() ? Vec3::Zero() : rng.vec(-5 * S, 5 * S);
    const Vec3 a = o + rng.vec(-S, S), b = o + rng.vec(-S, S);
    const Vec3 dir = (b - a).normalized();
    const Vec3 m = rng.orthogonal_unit(dir);
    const int k = 2 + (i % 13);  // width exponent 2..14
    const Scalar width = (b - a).norm() * std::pow(10.0, -k);
    const Vec3 c = a + rng.uniform(-0.5, 1.5) * (b - a) + width * m;
    Vec3 p;
    switch (i % 3) {
      case 0: p = o + rng.vec(-S, S); break;
      case 1: p = a + rng.uniform(0, 1) * (b - a) + rng.uniform(0, 1) * (c - b); break;  // on it
      default: p = a + rng.uniform(-0.2, 1.2) * (c - a) + rng.vec(-1e-3, 1e-3) * width; break;
    }
    check_point_triangle(ck, {p, a, b, c});
  }
  EXPECT_EQ(ck.failures(), 0);
}

TEST(PointTriangle, RigidMotionInvariance) {
  Rng rng("PointTriangle.RigidMotionInvariance", 9005);
  Checker ck("point_triangle rigid motion");
  for (int i = 0; i < 20000; ++i) {
    const Scalar S = rng.scale(-2, 2);
    const Tri c{rng.vec(-2 * S, 2 * S), rng.vec(-S, S), rng.vec(-S, S), rng.vec(-S, S)};
    const Eigen::Matrix3d R = rng.rotation();
    const Vec3 T = rng.vec(-10 * S, 10 * S);
    const Tri m{R * c.p + T, R * c.a + T, R * c.b + T, R * c.c + T};
    const Scalar L = max_abs_coord({c.p, c.a, c.b, c.c, m.p, m.a, m.b, m.c});
    ck.count();
    ck.close("distance", std::sqrt(point_triangle(m.p, m.a, m.b, m.c).sqr_distance),
             std::sqrt(point_triangle(c.p, c.a, c.b, c.c).sqr_distance), L, 2 * kTolUlps,
             json_case("point_triangle", {c.p, c.a, c.b, c.c}));
  }
  EXPECT_EQ(ck.failures(), 0);
}

TEST(PointTriangle, ExactCornersAndSides) {
  const Vec3 a(0, 0, 0), b(2, 0, 0), c(0, 2, 0);
  const PointTriangleResult va = point_triangle(Vec3(-1, -1, 1), a, b, c);
  EXPECT_EQ(va.region, TriangleRegion::VertexA);
  EXPECT_EQ(va.closest, a);
  EXPECT_EQ(va.barycentric, Vec3(1, 0, 0));
  EXPECT_EQ(va.sqr_distance, 3.0);
  const PointTriangleResult vb = point_triangle(Vec3(3, -1, 0), a, b, c);
  EXPECT_EQ(vb.region, TriangleRegion::VertexB);
  EXPECT_EQ(vb.closest, b);
  const PointTriangleResult ebc = point_triangle(Vec3(2, 2, 5), a, b, c);
  EXPECT_EQ(ebc.region, TriangleRegion::EdgeBC);
  EXPECT_EQ(ebc.closest, Vec3(1, 1, 0));
  EXPECT_EQ(ebc.sqr_distance, 2.0 + 25.0);
  const PointTriangleResult face = point_triangle(Vec3(0.5, 0.5, -2), a, b, c);
  EXPECT_EQ(face.region, TriangleRegion::Face);
  EXPECT_EQ(face.sqr_distance, 4.0);
  EXPECT_EQ(face.barycentric, Vec3(0.5, 0.25, 0.25));
  // A point exactly above a side, on the boundary of the face region.
  const PointTriangleResult eab = point_triangle(Vec3(1, 0, 3), a, b, c);
  EXPECT_EQ(eab.region, TriangleRegion::EdgeAB);
  EXPECT_EQ(eab.sqr_distance, 9.0);
  // Degenerate triangle: all corners on the x axis; closest point at the far corner.
  const PointTriangleResult deg = point_triangle(Vec3(5, 1, 0), a, b, Vec3(4, 0, 0));
  EXPECT_EQ(deg.region, TriangleRegion::VertexC);
  EXPECT_EQ(deg.sqr_distance, 2.0);
}

}  // namespace
}  // namespace crumple::geometry
