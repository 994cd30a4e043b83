// A material per unit area and length (`Material`): the same deformation of the same surface
// stores the same energy whatever the mesh resolution.
#include <crumple/core/error.hpp>
#include <crumple/mesh/shapes.hpp>
#include <crumple/sim/forces.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

namespace crumple::sim {
namespace {

/// n × n lattice of side 1 in the plane z = 0.
TriMesh square(Index n) { return shapes::lattice(n, n, 1, 1); }

Energy energy_of(const Cloth& c, const Positions& x) {
  State s{x, Positions(x.size(), Vec3::Zero()), 0};
  return compute_energy(c.model, ForceField{Vec3::Zero(), 0, {}}, s);
}

TEST(Material, MassAndUniformStretchDoNotDependOnResolution) {
  Material m;
  m.density = 0.3;
  m.stretch = 500;
  m.shear = 0;
  m.bending = 0;
  const Scalar strain = 0.01;
  for (Index n : {4, 8, 16, 32}) {
    const Cloth c = make_cloth(square(n), m);
    Scalar mass = 0;
    for (Scalar mi : c.model.mass()) mass += mi;
    EXPECT_NEAR(mass, 0.3, 1e-12) << n;
    Positions x = c.state.x;
    for (Vec3& p : x) p *= 1 + strain;
    // Every spring is stretched by strain × L: ½ Σ k (εL)² = ½ stretch ε² Σ A_e = ½ stretch ε² A.
    EXPECT_NEAR(energy_of(c, x).spring, 0.5 * 500 * strain * strain, 1e-12) << n;
  }
}

TEST(Material, RigidMotionIsFree) {
  const Cloth c = make_cloth(square(6), Material{});
  ASSERT_FALSE(c.model.hinges().empty());
  const Eigen::AngleAxis<Scalar> rotation(0.7, Vec3(1, 2, 3).normalized());
  Positions x = c.state.x;
  for (Vec3& p : x) p = rotation * p + Vec3(0.3, -2, 5);
  const Energy e = energy_of(c, x);
  EXPECT_NEAR(e.spring, 0, 1e-20);
  EXPECT_NEAR(e.bending, 0, 1e-20);
}

/// The lattice rolled onto a cylinder of radius R (arc length kept) stores the plate's bending
/// energy ½ D A / R² at every resolution: the hinges discretise the same continuum energy.
TEST(Material, CylinderBendingEnergyMatchesThePlate) {
  Material m;
  m.stretch = 0;
  m.shear = 0;
  m.bending = 2e-3;
  const Scalar radius = 0.8;
  const Scalar plate = 0.5 * m.bending * 1.0 / (radius * radius);
  for (const bool across_x : {true, false}) {
    for (Index n : {8, 16, 32, 64}) {
      const Cloth c = make_cloth(square(n), m);
      Positions x = c.state.x;
      for (Vec3& p : x) {
        const Scalar u = across_x ? p.x() : p.y();
        const Scalar angle = u / radius;
        const Vec3 q(radius * std::sin(angle), across_x ? p.y() : radius * std::sin(angle), radius * (1 - std::cos(angle)));
        p = across_x ? Vec3(q.x(), p.y(), q.z()) : Vec3(p.x(), q.y(), q.z());
      }
      const Scalar ratio = energy_of(c, x).bending / plate;
      std::printf("cylinder across %s, n=%d: hinge energy / plate energy = %.4f\n", across_x ? "x" : "y", n, ratio);
      // The boundary strip (hinges only on interior edges) loses O(1/n) of the area.
      EXPECT_NEAR(ratio, 1.0, 1.5 / n) << n;
    }
  }
}

/// Spring and hinge forces are minus the energy's gradient, and the hinges' Jacobian is the
/// forces' gradient (central differences on a randomly bent cloth).
TEST(Material, HingeForcesAndJacobianAreConsistent) {
  Material m;
  m.bending = 0.05;
  m.damping = 0;
  Cloth c = make_cloth(square(3), m);
  Positions x = c.state.x;
  for (std::size_t i = 0; i < x.size(); ++i) {
    x[i] += 0.05 * Vec3(std::sin(3.0 * i), std::cos(5.0 * i), std::sin(7.0 * i + 1));
  }
  const ForceField none{Vec3::Zero(), 0, {}};
  const Positions zero(x.size(), Vec3::Zero());
  std::vector<Vec3> f;
  compute_forces(c.model, none, x, zero, f);
  const Scalar eps = 1e-6;
  for (std::size_t i = 0; i < x.size(); ++i) {
    for (int a = 0; a < 3; ++a) {
      Positions plus = x, minus = x;
      plus[i][a] += eps;
      minus[i][a] -= eps;
      const Scalar de = (energy_of(c, plus).total() - energy_of(c, minus).total()) / (2 * eps);
      EXPECT_NEAR(f[i][a], -de, 1e-5 * (1 + std::abs(de))) << i << "," << a;
    }
  }
  // The bending Jacobian alone: a model with hinges and no springs.
  m.stretch = 0;
  m.shear = 0;
  c = make_cloth(square(3), m);
  const Eigen::MatrixXd bend = Eigen::MatrixXd(compute_force_jacobians(c.model, none, x).dfdx);
  for (std::size_t i = 0; i < x.size(); ++i) {
    for (int a = 0; a < 3; ++a) {
      Positions plus = x, minus = x;
      plus[i][a] += eps;
      minus[i][a] -= eps;
      std::vector<Vec3> fp, fm;
      compute_forces(c.model, none, plus, zero, fp);
      compute_forces(c.model, none, minus, zero, fm);
      for (std::size_t j = 0; j < x.size(); ++j) {
        for (int b = 0; b < 3; ++b) {
          const Scalar numeric = (fp[j][b] - fm[j][b]) / (2 * eps);
          EXPECT_NEAR(bend(static_cast<Eigen::Index>(3 * j) + b, static_cast<Eigen::Index>(3 * i) + a), numeric,
                      1e-6 * (1 + std::abs(numeric)));
        }
      }
    }
  }
  EXPECT_GT(bend.norm(), 0);
}

TEST(Material, BadParametersAreRejected) {
  Material m;
  m.stretch = -1;
  EXPECT_THROW(make_cloth(square(2), m), InputError);
  m = Material{};
  m.density = 0;
  EXPECT_THROW(make_cloth(square(2), m), InputError);
  m = Material{};
  m.bending = std::nan("");
  EXPECT_THROW(make_cloth(square(2), m), InputError);
}

}  // namespace
}  // namespace crumple::sim
