// Rigid obstacles: signed distances, projection, inelastic normal response, friction, motion.
#include <crumple/response/obstacle.hpp>

#include <gtest/gtest.h>

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

}  // namespace
}  // namespace crumple::response
