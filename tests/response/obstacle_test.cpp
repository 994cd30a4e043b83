// Rigid obstacles: signed distances, projection, inelastic normal response, friction, motion.
#include <crumple/response/obstacle.hpp>

#include <gtest/gtest.h>

#include <random>
#include <vector>

namespace crumple::response {
namespace {

TEST(Obstacle, SignedDistances) {
  const Sphere s{Vec3(1, 0, 0), 0.5};
  EXPECT_DOUBLE_EQ(query(s, Vec3(3, 0, 0)).distance, 1.5);
  EXPECT_DOUBLE_EQ(query(s, Vec3(1, 0.25, 0)).distance, -0.25);
  EXPECT_TRUE(query(s, Vec3(1, 0.25, 0)).normal.isApprox(Vec3::UnitY()));

  const Box b{Vec3::Zero(), Vec3(1, 2, 3)};
  EXPECT_DOUBLE_EQ(query(b, Vec3(2, 0, 0)).distance, 1);
  EXPECT_TRUE(query(b, Vec3(2, 0, 0)).normal.isApprox(Vec3::UnitX()));
  EXPECT_DOUBLE_EQ(query(b, Vec3(0, 1.5, 0)).distance, -0.5);
  EXPECT_TRUE(query(b, Vec3(0, 1.5, 0)).normal.isApprox(Vec3::UnitY()));
  EXPECT_NEAR(query(b, Vec3(2, 3, 0)).distance, std::sqrt(2.0), 1e-15);  // corner region
  Box rotated = b;
  rotated.rotation = Eigen::AngleAxis<Scalar>(std::numbers::pi / 2, Vec3::UnitZ()).toRotationMatrix();
  EXPECT_NEAR(query(rotated, Vec3(3, 0, 0)).distance, 1, 1e-12);  // x now sees the half extent 2

  const Plane p{Vec3(0, 1, 0), Vec3::UnitY()};
  EXPECT_DOUBLE_EQ(query(p, Vec3(5, 0.25, 7)).distance, -0.75);
}

TEST(Obstacle, ProjectsOutAndRemovesApproachingVelocity) {
  Obstacle o{Sphere{Vec3::Zero(), 1}};
  o.margin = 0.1;
  std::vector<Vec3> x{{0, 0.5, 0}, {0, 3, 0}, {0, 0.9, 0}};
  std::vector<Vec3> v{{0.2, -1, 0}, {0, -1, 0}, {0, -1, 0}};
  std::vector<Scalar> inv_mass{1, 1, 0};
  EXPECT_EQ(resolve_obstacle(o, 0, inv_mass, x, v), 1u);
  EXPECT_NEAR(x[0].y(), 1.1, 1e-15);
  EXPECT_EQ(v[0], Vec3(0.2, 0, 0)) << "frictionless: tangential velocity kept";
  EXPECT_EQ(x[1], Vec3(0, 3, 0));
  EXPECT_EQ(x[2], Vec3(0, 0.9, 0)) << "pinned vertices never move";
  EXPECT_NEAR(max_penetration(o, 0, x), 0.1, 1e-15);
}

TEST(Obstacle, CoulombFrictionReducesTangentialVelocity) {
  Obstacle floor{Plane{}};
  floor.friction = 0.5;
  std::vector<Vec3> x{{0, -0.01, 0}, {0, -0.01, 0}};
  std::vector<Vec3> v{{1, -1, 0}, {0.2, -1, 0}};
  std::vector<Scalar> inv_mass{1, 1};
  resolve_obstacle(floor, 0, inv_mass, x, v);
  EXPECT_NEAR(v[0].x(), 0.5, 1e-15);
  EXPECT_EQ(v[1], Vec3::Zero()) << "static friction stops a slow slide";
  EXPECT_EQ(x[0].y(), 0);
}

TEST(Obstacle, KinematicMotionWithStopTime) {
  Obstacle o{Sphere{Vec3::Zero(), 0.5}, Vec3(1, 0, 0), 2.0};
  EXPECT_EQ(std::get<Sphere>(o.at_time(1)).center, Vec3(1, 0, 0));
  EXPECT_EQ(std::get<Sphere>(o.at_time(5)).center, Vec3(2, 0, 0));
  EXPECT_EQ(o.velocity_at(1), Vec3(1, 0, 0));
  EXPECT_EQ(o.velocity_at(3), Vec3::Zero());
  // A moving sphere carries a resting vertex along its normal (relative velocity).
  std::vector<Vec3> x{{1.4, 0, 0}}, v{{0, 0, 0}};
  std::vector<Scalar> inv_mass{1};
  resolve_obstacle(o, 1, inv_mass, x, v);
  EXPECT_NEAR(x[0].x(), 1.5, 1e-15);
  EXPECT_NEAR(v[0].x(), 1.0, 1e-15);
}

// `resolve_obstacle` and `max_penetration` skip the exact query for vertices provably farther
// than the margin (a box's world bounding box, a sphere's radius): the result must be that of
// querying every vertex, bit for bit, also for points within rounding of the skip's bounds.
TEST(Obstacle, SkippingFarVerticesChangesNothing) {
  const auto reference = [](const Obstacle& o, Scalar t, std::span<const Scalar> inv_mass, std::vector<Vec3>& x,
                            std::vector<Vec3>& v) {
    const Shape shape = o.at_time(t);
    const Vec3 vo = o.velocity_at(t);
    std::size_t count = 0;
    Scalar deepest = 0;
    for (const Vec3& p : x) deepest = std::max(deepest, -query(shape, p).distance);
    for (std::size_t i = 0; i < x.size(); ++i) {
      const SurfaceQuery q = query(shape, x[i]);
      if (inv_mass[i] == 0 || !(q.distance < o.margin)) continue;
      ++count;
      x[i] += (o.margin - q.distance) * q.normal;
      const Vec3 vr = v[i] - vo;
      const Scalar vn = vr.dot(q.normal);
      if (vn < 0) {
        Vec3 vt = vr - vn * q.normal;
        const Scalar vt_len = vt.norm();
        const Scalar reduced = std::max<Scalar>(0, vt_len - o.friction * (-vn));
        vt = vt_len > 0 ? Vec3(vt * (reduced / vt_len)) : Vec3::Zero();
        v[i] = vo + vt;
      }
    }
    return std::pair{count, deepest};
  };
  Box box{Vec3(0.3, -0.2, 0.1), Vec3(0.05, 0.4, 1.0)};
  box.rotation = Eigen::AngleAxis<Scalar>(0.3, Vec3(1, 2, 3).normalized()).toRotationMatrix();
  Box wall{Vec3(1.1, 0.2, 0.5), Vec3(0.05, 0.4, 1.0)};  // axis-aligned: faces on the AABB's
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<Scalar> coord(-1.5, 1.5), unit(-1, 1);
  for (const Shape& shape : {Shape{box}, Shape{wall}, Shape{Sphere{Vec3(0.1, 0.2, -0.3), 0.6}}}) {
    Obstacle o{shape, Vec3(0.2, 0, 0), 1.0};
    o.margin = 0.01;
    o.friction = 0.3;
    std::vector<Vec3> x, v;
    std::vector<Scalar> inv_mass;
    const Shape now = o.at_time(0.5);
    for (int i = 0; i < 4000; ++i) {
      Vec3 p(coord(rng), coord(rng), coord(rng));
      if (i % 2 == 0) {  // onto the margin's surface or the AABB's bounds, within rounding
        const SurfaceQuery q = query(now, p);
        p -= (q.distance - (i % 4 == 0 ? o.margin : 0)) * q.normal;
        if (i % 8 == 2) {
          if (const auto* b = std::get_if<Box>(&now)) {
            const int k = i % 3;
            const Scalar reach = (b->rotation.cwiseAbs() * b->half_extents)[k] + o.margin;
            p[k] = b->center[k] + (p[k] < b->center[k] ? -reach : reach);
          }
        }
        p = p.unaryExpr([&](Scalar c) { return c * (1 + 1e-15 * unit(rng)); });
      }
      x.push_back(p);
      v.emplace_back(unit(rng), unit(rng), unit(rng));
      inv_mass.push_back(i % 17 == 0 ? 0 : 1);
    }
    std::vector<Vec3> x_ref = x, v_ref = v;
    const auto [count, deepest] = reference(o, 0.5, inv_mass, x_ref, v_ref);
    EXPECT_EQ(max_penetration(o, 0.5, x), deepest);
    EXPECT_EQ(resolve_obstacle(o, 0.5, inv_mass, x, v), count);
    EXPECT_GT(count, 100u) << "the points must straddle the margin";
    for (std::size_t i = 0; i < x.size(); ++i) {
      ASSERT_EQ(x[i], x_ref[i]) << i;
      ASSERT_EQ(v[i], v_ref[i]) << i;
    }
  }
}

// `resolve_obstacles` sweeps the vertices once with every obstacle, on threads: the result must
// be that of `resolve_obstacle` for each obstacle in turn over all vertices, bit for bit, where
// the obstacles overlap (a vertex pushed by one into the next) and on any thread count.
TEST(Obstacle, AllObstaclesInOneSweepEqualOneAfterTheOther) {
  Box box{Vec3(0.3, -0.2, 0.1), Vec3(0.2, 0.4, 1.0)};
  box.rotation = Eigen::AngleAxis<Scalar>(0.3, Vec3(1, 2, 3).normalized()).toRotationMatrix();
  std::vector<Obstacle> obstacles{
      Obstacle{Shape{box}, Vec3(0.2, 0, 0), 1.0, 0.3, 0.02},
      Obstacle{Shape{Sphere{Vec3(0.1, 0.2, -0.3), 0.6}}, Vec3(0, -0.4, 0), 0.25, 0.1, 0.01},
      Obstacle{Shape{Plane{Vec3(0, -0.3, 0), Vec3::UnitY()}}, Vec3::Zero(), 1.0, 0.5, 0.01},
      Obstacle{Shape{Box{Vec3(0.2, 0, 0), Vec3(0.1, 1.0, 0.3)}}, Vec3(-0.1, 0, 0), 1.0, 0.0, 0.03}};
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<Scalar> coord(-1.2, 1.2), unit(-1, 1);
  std::vector<Vec3> x, v;
  std::vector<Scalar> inv_mass;
  for (int i = 0; i < 20000; ++i) {
    x.emplace_back(coord(rng), coord(rng), coord(rng));
    v.emplace_back(unit(rng), unit(rng), unit(rng));
    inv_mass.push_back(i % 13 == 0 ? 0 : 1);
  }
  for (const Scalar t : {0.1, 0.5}) {
    std::vector<Vec3> x_ref = x, v_ref = v;
    std::size_t count = 0;
    std::vector<std::size_t> each;
    for (const Obstacle& o : obstacles) {
      each.push_back(resolve_obstacle(o, t, inv_mass, x_ref, v_ref));
      count += each.back();
    }
    for (const std::size_t c : each) EXPECT_GT(c, 200u) << "every obstacle must push vertices out";
    for (const int threads : {1, 2, 4}) {
      std::vector<Vec3> xs = x, vs = v;
      EXPECT_EQ(resolve_obstacles(obstacles, t, inv_mass, xs, vs, threads), count) << threads;
      for (std::size_t i = 0; i < x.size(); ++i) {
        ASSERT_EQ(xs[i], x_ref[i]) << "threads " << threads << ", vertex " << i;
        ASSERT_EQ(vs[i], v_ref[i]) << "threads " << threads << ", vertex " << i;
      }
    }
  }
}

}  // namespace
}  // namespace crumple::response
