// Mass-spring model construction and forces: validation, lumped masses, bending springs,
// Jacobians against finite differences, momentum of internal forces.
#include <crumple/core/error.hpp>
#include <crumple/mesh/shapes.hpp>
#include <crumple/sim/forces.hpp>

#include <gtest/gtest.h>

#include <random>

namespace crumple::sim {
namespace {

TEST(Model, RejectsBadInput) {
  EXPECT_THROW(Model::create({1, 1}, {{0, 0, 1, 0, 1}}, {}), InputError);
  EXPECT_THROW(Model::create({1, 1}, {{0, 2, 1, 0, 1}}, {}), InputError);
  EXPECT_THROW(Model::create({1, -1}, {}, {}), InputError);
  EXPECT_THROW(Model::create({1, 1}, {{0, 1, -5, 0, 1}}, {}), InputError);
  EXPECT_THROW(Model::create({1, 1, 1}, {}, {{0, 1, 5}}), InputError);
  ClothParams params;
  params.pins = {99};
  EXPECT_THROW(make_cloth(shapes::lattice(2, 2), params), InputError);
}

TEST(Model, ClothMassesSpringsAndDamping) {
  const TriMesh mesh = shapes::lattice(3, 2, 3, 2);  // 6 m², 12 faces, unit quads
  ClothParams params;
  params.density = 0.5;
  params.bending_stiffness = 7;
  params.pins = {0};
  const Cloth c = make_cloth(mesh, params);
  const Model& m = c.model;
  Scalar total = 0;
  for (Scalar x : m.mass()) total += x;
  EXPECT_NEAR(total + 0.5 * 0.5 / 3 * 2, 3.0, 1e-12) << "corner 0 touches two half-quad faces";
  EXPECT_EQ(m.mass()[0], 0);
  EXPECT_TRUE(m.pinned(0));
  const std::size_t structural = static_cast<std::size_t>(mesh.num_edges());
  std::size_t interior = 0;
  for (Index e = 0; e < mesh.num_edges(); ++e) interior += mesh.topology().edge_faces()[e].size() == 2;
  ASSERT_EQ(m.springs().size(), structural + interior);
  EXPECT_EQ(m.springs()[structural].stiffness, 7);
  // Damping coefficient: 2 ζ √(k μ) with μ the reduced mass.
  const Spring& s = m.springs()[5];
  const Scalar ma = m.mass()[static_cast<std::size_t>(s.a)], mb = m.mass()[static_cast<std::size_t>(s.b)];
  const Scalar mu = ma > 0 && mb > 0 ? ma * mb / (ma + mb) : std::max(ma, mb);
  EXPECT_NEAR(m.damping()[5], 2 * s.damping_ratio * std::sqrt(s.stiffness * mu), 1e-12);
  EXPECT_EQ(c.state.v, Positions(c.state.x.size(), Vec3::Zero()));
}

TEST(Forces, InternalForcesSumToZero) {
  const TriMesh mesh = shapes::lattice(4, 4);
  ClothParams params;
  params.bending_stiffness = 20;
  const Cloth c = make_cloth(mesh, params);
  std::mt19937_64 rng(4);
  std::uniform_real_distribution<double> u(-0.05, 0.05);
  State s = c.state;
  for (std::size_t i = 0; i < s.x.size(); ++i) {
    s.x[i] += Vec3(u(rng), u(rng), u(rng));
    s.v[i] = Vec3(u(rng), u(rng), u(rng));
  }
  std::vector<Vec3> f;
  compute_forces(c.model, ForceField{Vec3::Zero(), 0, {}}, s.x, s.v, f);
  Vec3 sum = Vec3::Zero();
  for (const Vec3& x : f) sum += x;
  EXPECT_LT(sum.norm(), 1e-12);
}

TEST(Forces, JacobiansMatchFiniteDifferences) {
  const TriMesh mesh = shapes::lattice(3, 3);
  ClothParams params;
  params.bending_stiffness = 20;
  params.damping_ratio = 0.3;
  const Cloth c = make_cloth(mesh, params);
  ForceField field;
  field.air_damping = 0.7;
  field.drag = DragForce{5, Vec3(1, 2, 3), 50, 2};
  std::mt19937_64 rng(9);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  State s = c.state;
  for (std::size_t i = 0; i < s.x.size(); ++i) {
    s.x[i] *= 1.3;  // every spring stretched: the transverse term is not clamped
    s.x[i] += 0.01 * Vec3(u(rng), u(rng), u(rng));
    s.v[i] = Vec3(u(rng), u(rng), u(rng));
  }
  const ForceJacobians j = compute_force_jacobians(c.model, field, s.x);
  const Eigen::MatrixXd dfdx(j.dfdx), dfdv(j.dfdv);
  EXPECT_LT((dfdx - dfdx.transpose()).norm(), 1e-9);
  EXPECT_LT((dfdv - dfdv.transpose()).norm(), 1e-9);
  const Scalar eps = 1e-6;
  std::vector<Vec3> fp, fm;
  Scalar worst_x = 0, worst_v = 0;
  for (std::size_t i = 0; i < s.x.size(); ++i) {
    for (int d = 0; d < 3; ++d) {
      State a = s, b = s;
      a.v[i][d] += eps;
      b.v[i][d] -= eps;
      compute_forces(c.model, field, a.x, a.v, fp);
      compute_forces(c.model, field, b.x, b.v, fm);
      for (std::size_t r = 0; r < s.x.size(); ++r) {
        for (int e = 0; e < 3; ++e) {
          const Scalar fd = (fp[r][e] - fm[r][e]) / (2 * eps);
          worst_v = std::max(worst_v, std::abs(fd - dfdv(static_cast<Eigen::Index>(3 * r + e),
                                                         static_cast<Eigen::Index>(3 * i + d))));
        }
      }
    }
  }
  // ∂f/∂x checked with zero velocities (the damping force's position derivative is neglected
  // by design, as in Baraff & Witkin).
  for (auto& v : s.v) v.setZero();
  for (std::size_t i = 0; i < s.x.size(); ++i) {
    for (int d = 0; d < 3; ++d) {
      State a = s, b = s;
      a.x[i][d] += eps;
      b.x[i][d] -= eps;
      compute_forces(c.model, field, a.x, a.v, fp);
      compute_forces(c.model, field, b.x, b.v, fm);
      for (std::size_t r = 0; r < s.x.size(); ++r) {
        for (int e = 0; e < 3; ++e) {
          const Scalar fd = (fp[r][e] - fm[r][e]) / (2 * eps);
          worst_x = std::max(worst_x, std::abs(fd - dfdx(static_cast<Eigen::Index>(3 * r + e),
                                                         static_cast<Eigen::Index>(3 * i + d))));
        }
      }
    }
  }
  EXPECT_LT(worst_x, 1e-5 * params.stiffness);
  EXPECT_LT(worst_v, 1e-6);
}

TEST(Forces, GravityAirAndDrag) {
  const Model m = Model::create({2, 0}, {}, {});
  ForceField field{Vec3(0, -10, 0), 0.5, DragForce{0, Vec3(1, 0, 0), 10, 3}};
  std::vector<Vec3> f;
  compute_forces(m, field, std::vector<Vec3>{Vec3::Zero(), Vec3::Zero()},
                 std::vector<Vec3>{Vec3(0, 1, 0), Vec3::Zero()}, f);
  // gravity 2*(0,-10,0), air -0.5*2*(0,1,0), drag 10*(1,0,0) - 3*(0,1,0)
  EXPECT_LT((f[0] - Vec3(10, -20 - 1 - 3, 0)).norm(), 1e-14);
  EXPECT_EQ(f[1], Vec3::Zero()) << "a pinned particle has mass 0";
}

}  // namespace
}  // namespace crumple::sim
