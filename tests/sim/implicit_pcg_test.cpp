// Implicit Euler's preconditioned conjugate gradient (`CgPreconditioner::Rest`) against a dense
// direct solve of the same backward Euler system, and against the Jacobi path
// (docs/simulation.md, "Integrators").
#include <crumple/mesh/shapes.hpp>
#include <crumple/sim/integrator.hpp>

#include <gtest/gtest.h>

#include <Eigen/Dense>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <vector>

namespace crumple::sim {
namespace {

using Dense = Eigen::Matrix<Scalar, Eigen::Dynamic, Eigen::Dynamic>;
using Vector = Eigen::Matrix<Scalar, Eigen::Dynamic, 1>;

/// A value in [-1, 1) from a fixed linear congruential sequence (the same on every platform).
Scalar noise(std::uint64_t& seed) {
  seed = seed * 6364136223846793005ULL + 1442695040888963407ULL;
  return static_cast<Scalar>(seed >> 11) / static_cast<Scalar>(1ULL << 52) - 1;
}

/// A 1 m square of the per-area material (structural springs, hinges with damping) on an
/// n × n lattice, pinned at two corners, its vertices moved by up to 30% of an edge and given
/// random velocities: springs stretched and compressed, hinges bent, so every block of the
/// system differs from the preconditioner's.
struct Crumpled {
  Cloth cloth;
  ForceField field;
  explicit Crumpled(Index n, Scalar stretch = 400) {
    const TriMesh mesh = shapes::lattice(n, n, 1, 1);
    Material m;
    m.stretch = stretch;
    m.pins = {0, n};
    cloth = make_cloth(mesh, m);
    std::uint64_t seed = 7;
    const Scalar edge = 1.0 / static_cast<Scalar>(n);
    for (std::size_t i = 0; i < cloth.state.x.size(); ++i) {
      if (cloth.model.pinned(static_cast<Index>(i))) continue;
      for (int c = 0; c < 3; ++c) {
        cloth.state.x[i][c] += 0.3 * edge * noise(seed);
        cloth.state.v[i][c] = 0.5 * noise(seed);
      }
    }
    field.air_damping = 0.2;
    field.drag = DragForce{n + 2, Vec3(0.5, 0.3, 0.2), 100, 1};
  }
};

/// The backward Euler system of one step, assembled densely from the force Jacobians (the
/// header's formula), with the anchors' terms (see `Anchor`) and the pinned rows and columns
/// replaced by the identity.
struct DenseSystem {
  Dense a;
  Vector b;
};

DenseSystem dense_system(const Model& model, const ForceField& field, const State& s, Scalar h,
                         const std::vector<Anchor>& anchors, Scalar stiffness) {
  const Index n = model.num_particles();
  const ForceJacobians j = compute_force_jacobians(model, field, s.x);
  std::vector<Vec3> f;
  compute_forces(model, field, s.x, s.v, f);
  Vector v0(3 * n), f0(3 * n);
  for (Index i = 0; i < n; ++i) {
    v0.segment<3>(3 * i) = s.v[static_cast<std::size_t>(i)];
    f0.segment<3>(3 * i) = f[static_cast<std::size_t>(i)];
  }
  const Dense dfdx = Dense(j.dfdx), dfdv = Dense(j.dfdv);
  DenseSystem d;
  d.a = -h * dfdv - h * h * dfdx;
  for (Index i = 0; i < 3 * n; ++i) d.a(i, i) += model.mass()[static_cast<std::size_t>(i / 3)];
  d.b = h * (f0 + h * dfdx * v0);
  const Dense before = d.a;
  for (const Anchor& anchor : anchors) {
    const auto k = static_cast<std::size_t>(anchor.vertex);
    if (model.pinned(anchor.vertex)) continue;
    const Scalar diagonal = stiffness * before.block<3, 3>(3 * anchor.vertex, 3 * anchor.vertex).trace() / 3;
    const Vec3 dir = anchor.direction;
    const Scalar offset = std::max(anchor.offset, h * dir.dot(s.v[k]));
    d.a.block<3, 3>(3 * anchor.vertex, 3 * anchor.vertex) += diagonal * (dir * dir.transpose());
    d.b.segment<3>(3 * anchor.vertex) += h * (diagonal / (h * h)) * (offset - h * dir.dot(s.v[k])) * dir;
  }
  for (Index i = 0; i < n; ++i) {
    if (!model.pinned(i)) continue;
    d.a.middleRows(3 * i, 3).setZero();
    d.a.middleCols(3 * i, 3).setZero();
    d.a.block<3, 3>(3 * i, 3 * i).setIdentity();
    d.b.segment<3>(3 * i).setZero();
  }
  return d;
}

struct Step {
  State state;
  int iterations = 0;
};

Step implicit_step(const Crumpled& c, CgPreconditioner preconditioner, Scalar h, const std::vector<Anchor>& anchors,
                   Scalar stiffness, int threads = 1) {
  IntegratorOptions options;
  options.cg_preconditioner = preconditioner;
  options.threads = threads;
  auto integrator = make_integrator(IntegratorKind::ImplicitEuler, options);
  integrator->set_anchors(anchors, stiffness);
  Step s{c.cloth.state, 0};
  integrator->step(c.cloth.model, c.field, s.state, h);
  s.iterations = integrator->last_iterations();
  return s;
}

/// The step's Δv (v₁ − v₀) solves the dense system to the CG tolerance (a relative residual of
/// 1e-8; allowed 2e-8 for the rounding of v₁ − v₀ and of the recurrence), and lies within the
/// tolerance times the condition number of the direct solution, with either preconditioner,
/// with pins, hinges, drag, air damping and anchors (one of them on a pinned particle, which
/// does nothing). Pinned particles keep their velocity exactly. The preconditioned solve takes
/// fewer iterations than Jacobi here too (so it is not the fallback that answered).
TEST(ImplicitPcg, SolvesTheBackwardEulerSystemToTheTolerance) {
  const Crumpled c(8);
  const Scalar h = 1.0 / 600;
  const std::vector<Anchor> anchors{{20, Vec3(0.6, 0.8, 0), 2e-3}, {33, Vec3::UnitY(), 0}, {0, Vec3::UnitX(), 1e-3}};
  const Scalar stiffness = 1.5;
  const DenseSystem d = dense_system(c.cloth.model, c.field, c.cloth.state, h, anchors, stiffness);
  const Vector exact = d.a.ldlt().solve(d.b);
  const Eigen::SelfAdjointEigenSolver<Dense> spectrum(d.a);
  const Scalar condition = spectrum.eigenvalues().maxCoeff() / spectrum.eigenvalues().minCoeff();
  int jacobi_iterations = 0;
  for (const CgPreconditioner preconditioner : {CgPreconditioner::Diagonal, CgPreconditioner::Rest}) {
    const Step step = implicit_step(c, preconditioner, h, anchors, stiffness);
    if (preconditioner == CgPreconditioner::Diagonal) {
      jacobi_iterations = step.iterations;
    } else {
      EXPECT_LT(step.iterations, jacobi_iterations) << "the preconditioned solve, not the Jacobi fallback";
    }
    Vector dv(d.b.size());
    for (std::size_t i = 0; i < step.state.v.size(); ++i) {
      dv.segment<3>(3 * static_cast<Eigen::Index>(i)) = step.state.v[i] - c.cloth.state.v[i];
      if (c.cloth.model.pinned(static_cast<Index>(i))) {
        EXPECT_EQ(step.state.v[i], c.cloth.state.v[i]);
      }
    }
    const Scalar residual = (d.a * dv - d.b).norm() / d.b.norm();
    const Scalar error = (dv - exact).norm() / exact.norm();
    std::printf("%s: %d iterations, relative residual %.3g, error %.3g (condition %.3g)\n",
                preconditioner == CgPreconditioner::Rest ? "rest" : "diagonal", step.iterations, residual, error,
                condition);
    EXPECT_GT(step.iterations, 0);
    EXPECT_LT(residual, 2e-8);
    EXPECT_LT(error, 2e-8 * condition);
  }
}

/// On a stiff cloth (stretch 10⁴ N/m at n = 16, h = 1/240 s) Jacobi needs ~√(condition number)
/// iterations (measured: 255); the prefactored rest matrix plus the diagonal blocks needs a
/// third of them or fewer (76), at the same tolerance, with and without anchors; and the step
/// is the same bits on one and two threads.
TEST(ImplicitPcg, NeedsFarFewerIterationsThanJacobi) {
  const Crumpled c(16, 1e4);
  const Scalar h = 1.0 / 240;
  const std::vector<Anchor> anchors{{100, Vec3::UnitX(), 1e-3}};
  for (const Scalar stiffness : {0.0, 1.0}) {
    const std::vector<Anchor> used = stiffness > 0 ? anchors : std::vector<Anchor>{};
    const Step jacobi = implicit_step(c, CgPreconditioner::Diagonal, h, used, stiffness);
    const Step rest = implicit_step(c, CgPreconditioner::Rest, h, used, stiffness);
    std::printf("anchor stiffness %g: Jacobi %d iterations, rest %d\n", stiffness, jacobi.iterations, rest.iterations);
    EXPECT_GT(jacobi.iterations, 100);
    EXPECT_LE(3 * rest.iterations, jacobi.iterations);
    Scalar apart = 0;
    for (std::size_t i = 0; i < rest.state.v.size(); ++i) {
      apart = std::max(apart, (rest.state.v[i] - jacobi.state.v[i]).norm());
    }
    EXPECT_LT(apart, 1e-5) << "the two solves agree within the tolerance";
    const Step two = implicit_step(c, CgPreconditioner::Rest, h, used, stiffness, 2);
    EXPECT_EQ(two.state.x, rest.state.x);
    EXPECT_EQ(two.state.v, rest.state.v);
  }
}

}  // namespace
}  // namespace crumple::sim
