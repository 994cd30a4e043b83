// Integrators on a single spring against the analytic solution, stability, pinned particles.
#include <crumple/core/error.hpp>
#include <crumple/mesh/shapes.hpp>
#include <crumple/sim/integrator.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

namespace crumple::sim {
namespace {

/// Particle 0 pinned at the origin, particle 1 (mass m) on a spring of rest length L along x,
/// released from L + A at rest, no gravity, no damping: x(t) = L + A cos(ω t), ω = √(k/m).
struct SingleSpring {
  Scalar k = 100, m = 1, rest = 1, amplitude = 0.1;
  Model model = Model::create({0, m}, {{0, 1, k, 0, rest}}, {});
  ForceField field{Vec3::Zero(), 0, {}};
  State state{{Vec3::Zero(), Vec3(rest + amplitude, 0, 0)}, {Vec3::Zero(), Vec3::Zero()}, 0};
  Scalar omega() const { return std::sqrt(k / m); }
  Scalar exact(Scalar t) const { return rest + amplitude * std::cos(omega() * t); }
  Scalar energy() const { return compute_energy(model, field, state).total(); }
  Scalar energy0() const { return 0.5 * k * amplitude * amplitude; }
};

TEST(Integrator, NamesRoundTrip) {
  for (IntegratorKind k : all_integrators()) EXPECT_EQ(parse_integrator(to_string(k)), k);
  try {
    parse_integrator("leapfrog");
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("implicit-euler"), std::string::npos) << e.what();
  }
}

TEST(Integrator, Rk4FollowsTheAnalyticSolution) {
  SingleSpring s;
  auto integrator = make_integrator(IntegratorKind::Rk4);
  const Scalar h = 1e-3;
  Scalar worst = 0;
  for (int i = 0; i < 2000; ++i) {  // ~3 periods
    integrator->step(s.model, s.field, s.state, h);
    worst = std::max(worst, std::abs(s.state.x[1].x() - s.exact(s.state.time)));
  }
  EXPECT_LT(worst, 1e-9);
  EXPECT_NEAR(s.energy(), s.energy0(), 1e-9 * s.energy0());
}

TEST(Integrator, SymplecticEulerKeepsEnergyBoundedAndPhaseClose) {
  SingleSpring s;
  auto integrator = make_integrator(IntegratorKind::SymplecticEuler);
  const Scalar h = 1e-3;
  Scalar worst_energy = 0, worst_x = 0;
  for (int i = 0; i < 20000; ++i) {  // ~30 periods
    integrator->step(s.model, s.field, s.state, h);
    worst_energy = std::max(worst_energy, std::abs(s.energy() - s.energy0()));
    worst_x = std::max(worst_x, std::abs(s.state.x[1].x() - s.exact(s.state.time)));
  }
  EXPECT_LT(worst_energy, 0.01 * s.energy0()) << "oscillates within O(h ω) of the true energy";
  EXPECT_LT(worst_x, 0.05 * s.amplitude);
}

TEST(Integrator, ExplicitEulerGainsEnergyAndImplicitEulerLosesIt) {
  SingleSpring e, i;
  auto explicit_euler = make_integrator(IntegratorKind::ExplicitEuler);
  auto implicit_euler = make_integrator(IntegratorKind::ImplicitEuler);
  const Scalar h = 1e-3;
  Scalar previous = i.energy();
  for (int n = 0; n < 6000; ++n) {
    explicit_euler->step(e.model, e.field, e.state, h);
    implicit_euler->step(i.model, i.field, i.state, h);
    const Scalar now = i.energy();
    EXPECT_LE(now, previous * (1 + 1e-12)) << "step " << n;
    previous = now;
  }
  // Analytic growth per step of explicit Euler on an oscillator: factor (1 + (h ω)²).
  const Scalar hw = h * e.omega();
  const Scalar growth = std::pow(1 + hw * hw, 6000);
  EXPECT_NEAR(e.energy() / e.energy0(), growth, 1e-3 * growth);
  EXPECT_GT(growth, 1.5);
  EXPECT_LT(i.energy(), 0.9 * i.energy0());
  EXPECT_NEAR(i.state.x[1].x(), i.rest, i.amplitude) << "still oscillating around the rest length";
}

TEST(Integrator, ImplicitStaysStableWhereExplicitDiverges) {
  // A stiff 6x6 cloth pinned at one corner under gravity: h ω ≈ 30.
  const TriMesh mesh = shapes::lattice(6, 6);
  ClothParams params;
  params.stiffness = 1e5;
  params.density = 0.1;
  params.damping_ratio = 0;
  params.pins = {0};
  const Cloth cloth = make_cloth(mesh, params);
  const ForceField field;
  const Scalar h = 0.01;
  const Scalar diag = std::sqrt(2.0);

  State explicit_state = cloth.state;
  auto ex = make_integrator(IntegratorKind::ExplicitEuler);
  bool diverged = false;
  for (int n = 0; n < 200 && !diverged; ++n) {
    ex->step(cloth.model, field, explicit_state, h);
    for (const Vec3& p : explicit_state.x) diverged |= !std::isfinite(p.norm()) || p.norm() > 1e3;
  }
  EXPECT_TRUE(diverged);

  State implicit_state = cloth.state;
  auto im = make_integrator(IntegratorKind::ImplicitEuler);
  for (int n = 0; n < 200; ++n) {
    im->step(cloth.model, field, implicit_state, h);
    for (const Vec3& p : implicit_state.x) {
      ASSERT_TRUE(std::isfinite(p.norm()));
      ASSERT_LT(p.norm(), 1.1 * diag) << "stays within the cloth's reach from the pin";
    }
  }
  EXPECT_GT(im->last_iterations(), 0);
}

TEST(Integrator, PinnedParticlesNeverMove) {
  const TriMesh mesh = shapes::lattice(4, 4);
  ClothParams params;
  params.pins = {0, 4};
  const Cloth cloth = make_cloth(mesh, params);
  ForceField field;
  field.air_damping = 0.1;
  field.drag = DragForce{0, Vec3(5, 5, 5), 100, 1};  // dragging a pinned particle does nothing
  for (IntegratorKind kind : all_integrators()) {
    State s = cloth.state;
    auto integrator = make_integrator(kind);
    for (int n = 0; n < 100; ++n) integrator->step(cloth.model, field, s, 1e-4);
    EXPECT_EQ(s.x[0], cloth.state.x[0]) << to_string(kind);
    EXPECT_EQ(s.x[4], cloth.state.x[4]) << to_string(kind);
    EXPECT_EQ(s.v[0], Vec3::Zero()) << to_string(kind);
    EXPECT_NE(s.x[24], cloth.state.x[24]) << to_string(kind) << ": free particles fall";
    EXPECT_NEAR(s.time, 100 * 1e-4, 1e-15);
  }
}

TEST(Integrator, DeterministicBitForBit) {
  const TriMesh mesh = shapes::lattice(5, 5);
  ClothParams params;
  params.pins = {0};
  params.bending_stiffness = 10;
  const Cloth cloth = make_cloth(mesh, params);
  for (IntegratorKind kind : all_integrators()) {
    State a = cloth.state, b = cloth.state;
    auto ia = make_integrator(kind), ib = make_integrator(kind);
    for (int n = 0; n < 50; ++n) {
      ia->step(cloth.model, ForceField{}, a, 1e-3);
      ib->step(cloth.model, ForceField{}, b, 1e-3);
    }
    EXPECT_EQ(a.x, b.x) << to_string(kind);
    EXPECT_EQ(a.v, b.v) << to_string(kind);
  }
}

// A pull repeated at every step on one vertex of a stiff cloth (κ = k h²/m ≈ 17 per spring):
// moved before each step, the step takes it back (the vertex ends within δ/κ of where it was);
// held inside each step as an anchor (stiffness 1: as stiff as the step's own diagonal), the
// springs share it with the neighbours, and the steps keep it. The anchor's direction is in the cloth's plane, where the springs resist at
// first order.
TEST(Integrator, AnchorHoldsAPullTheNextStepWouldTakeBack) {
  const TriMesh mesh = shapes::lattice(8, 8);
  ClothParams params;
  params.stiffness = 1e4;
  params.damping_ratio = 0;
  params.pins = {0, 8, 72, 80};  // the corners
  const Cloth cloth = make_cloth(mesh, params);
  const ForceField field{Vec3::Zero(), 0, {}};
  const Scalar h = 1.0 / 600, delta = 1e-3;
  const Index centre = 40;
  const auto c = static_cast<std::size_t>(centre);
  const Scalar kappa = params.stiffness * h * h * cloth.model.inv_mass()[c];
  ASSERT_GT(kappa, 10);
  constexpr int kSteps = 20;

  State after = cloth.state;  // the pull after each step
  auto moved = make_integrator(IntegratorKind::ImplicitEuler);
  for (int n = 0; n < kSteps; ++n) {
    after.x[c].x() += delta;
    moved->step(cloth.model, field, after, h);
  }
  State held = cloth.state;  // the pull inside each step
  auto anchored = make_integrator(IntegratorKind::ImplicitEuler);
  ASSERT_TRUE(anchored->takes_anchors());
  const Anchor anchor{centre, Vec3::UnitX(), delta};
  for (int n = 0; n < kSteps; ++n) {
    anchored->set_anchors({&anchor, 1}, 1);
    anchored->step(cloth.model, field, held, h);
  }
  const Scalar x0 = cloth.state.x[c].x();
  EXPECT_LT(after.x[c].x() - x0, 2 * delta / kappa) << "the steps take the pulls back";
  EXPECT_GT(held.x[c].x() - x0, 2 * delta) << "the steps keep the held pulls";
  // The neighbours follow the held pull.
  EXPECT_GT(held.x[c + 1].x() - cloth.state.x[c + 1].x(), delta);
  // An anchor on a pinned particle does nothing; removed anchors act no more.
  State pinned = cloth.state;
  const Anchor on_pin{0, Vec3::UnitX(), delta};
  anchored->set_anchors({&on_pin, 1}, 1);
  anchored->step(cloth.model, field, pinned, h);
  EXPECT_EQ(pinned.x[0], cloth.state.x[0]);
  anchored->set_anchors({}, 0);
  State free = cloth.state;
  anchored->step(cloth.model, field, free, h);
  EXPECT_EQ(free.x, cloth.state.x) << "at rest, nothing moves";
}

}  // namespace
}  // namespace crumple::sim
