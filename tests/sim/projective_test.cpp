// Projective dynamics (the fast default step) and resolution-independent drapes.
#include <crumple/mesh/shapes.hpp>
#include <crumple/sim/scene.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <utility>
#include <vector>

namespace crumple::sim {
namespace {

/// A 1 m square cloth of the default material (`Material{}`) on an n × n lattice, pinned at two
/// adjacent corners, falling from horizontal with strong air damping (5 /s) so it comes to
/// rest; `frames` frames of 1/60 s, one projective step of 10 Chebyshev-accelerated iterations.
Bounds hang(Index n, int frames) {
  TriMesh flat = shapes::lattice(n, n, 1, 1);
  Positions x = flat.positions();
  for (Vec3& p : x) p = Vec3(p.x(), 0, p.y());
  const TriMesh mesh = TriMesh::create(std::move(x), {flat.topology().faces().begin(), flat.topology().faces().end()});
  Material m;
  m.pins = {0, n};  // lattice vertices (0, 0) and (n, 0)
  Cloth c = make_cloth(mesh, m);
  ForceField field;
  field.air_damping = 5;
  IntegratorOptions options;
  options.projective_iterations = 10;
  options.projective_rho = 0.8;
  auto integrator = make_integrator(IntegratorKind::Projective, options);
  for (int k = 0; k < frames; ++k) integrator->step(c.model, field, c.state, 1.0 / 60);
  return compute_bounds(c.state.x);
}

/// The same material hanging from two corners at n = 16, 32, 64 (16 and 32 under the
/// sanitizers) rests alike after 1.5 s: the sag (lowest point) and the extent in the pins'
/// plane agree with the finest run's within 2% of the side (1 m), i.e. 2 cm; the out-of-plane
/// extent (the sheet's waves, z) within 5 cm.
TEST(Projective, HangingClothRestsAlikeAtEveryResolution) {
#ifdef CRUMPLE_SANITIZED
  const std::vector<Index> sizes{16, 32};
#else
  const std::vector<Index> sizes{16, 32, 64};
#endif
  std::vector<Bounds> boxes;
  for (Index n : sizes) {
    boxes.push_back(hang(n, 90));
    const Bounds& b = boxes.back();
    std::printf("n=%d: box (%.4f %.4f %.4f) .. (%.4f %.4f %.4f)\n", n, b.min.x(), b.min.y(), b.min.z(), b.max.x(),
                b.max.y(), b.max.z());
  }
  const Bounds& finest = boxes.back();
  for (std::size_t k = 0; k + 1 < boxes.size(); ++k) {
    SCOPED_TRACE("n=" + std::to_string(sizes[k]));
    for (int a = 0; a < 3; ++a) {
      const Scalar tolerance = a == 2 ? 0.05 : 0.02;
      EXPECT_NEAR(boxes[k].min[a], finest.min[a], tolerance) << "axis " << a;
      EXPECT_NEAR(boxes[k].max[a], finest.max[a], tolerance) << "axis " << a;
    }
  }
  EXPECT_LT(finest.min.y(), -0.95) << "hangs about its side's length below the pins";
  EXPECT_GT(finest.min.y(), -1.1);
}

/// A 6 × 6 cloth of the default material without damping, pinned at one corner.
Cloth small_cloth() {
  Material m;
  m.damping = 0;
  m.pins = {0};
  return make_cloth(shapes::lattice(6, 6, 1, 1), m);
}

/// At a small step, projective dynamics follows the thesis' implicit Euler: after 0.1 s of
/// free fall from the flat state (1,000 steps of 1e-4 s) every particle is within 0.01 mm of it.
TEST(Projective, AgreesWithImplicitEulerAtSmallSteps) {
  const Cloth c = small_cloth();
  const ForceField field;
  State a = c.state, b = c.state;
  auto projective = make_integrator(IntegratorKind::Projective);
  auto implicit = make_integrator(IntegratorKind::ImplicitEuler);
  for (int k = 0; k < 1000; ++k) {
    projective->step(c.model, field, a, 1e-4);
    implicit->step(c.model, field, b, 1e-4);
  }
  Scalar worst = 0, moved = 0;
  for (std::size_t i = 0; i < a.x.size(); ++i) {
    worst = std::max(worst, (a.x[i] - b.x[i]).norm());
    moved = std::max(moved, (a.x[i] - c.state.x[i]).norm());
  }
  std::printf("projective vs implicit Euler after 0.1 s: %.3g m apart (particles moved up to %.3g m)\n", worst, moved);
  EXPECT_GT(moved, 0.04) << "the cloth has fallen";
  EXPECT_LT(worst, 1e-5);
}

/// At one step per frame and beyond (1/30 s), without air or spring damping, the step stays
/// bounded and loses energy: the total (kinetic + springs + hinges + gravity) never rises above
/// its start by more than 1e-9 J and ends well below it.
TEST(Projective, StableAndDissipativeAtLargeSteps) {
  for (const Scalar h : {1.0 / 60, 1.0 / 30}) {
    const Cloth c = small_cloth();
    const ForceField field;
    State s = c.state;
    const Scalar e0 = compute_energy(c.model, field, s).total();
    auto integrator = make_integrator(IntegratorKind::Projective);
    Scalar highest = e0;
    for (int k = 0; k < 300; ++k) {
      integrator->step(c.model, field, s, h);
      highest = std::max(highest, compute_energy(c.model, field, s).total());
      for (const Vec3& p : s.x) ASSERT_LT(p.norm(), 1.2 * std::sqrt(2.0)) << "within reach of the pin";
    }
    const Scalar e1 = compute_energy(c.model, field, s).total();
    std::printf("h=%.4f: energy %.5f -> %.5f J (highest %.5f)\n", h, e0, e1, highest);
    EXPECT_LE(highest, e0 + 1e-9);
    EXPECT_LT(e1, e0 - 0.1 * std::abs(e0));
  }
}

/// The scenes' default step (projective, with response) runs at 1/30 s frames of one step.
TEST(Projective, ScenesRunAtOneStepPerFrame) {
  for (const char* spec : {"cloth-on-sphere:n=8", "crumple:n=8,push-time=1"}) {
    Scene s = make_scene(SceneSpec::parse(spec), 1);
    ASSERT_EQ(s.settings.integrator, IntegratorKind::Projective) << spec;
    Settings settings = s.settings;
    settings.dt = 1.0 / 30;
    settings.substeps = 1;
    settings.detector.threads = 1;
    Simulation sim(std::move(s.model), std::move(s.state), s.field, std::move(s.obstacles), std::move(s.kinematics),
                   settings);
    for (int f = 0; f < 60; ++f) {
      const FrameStats stats = sim.advance_frame();
      EXPECT_LE(stats.obstacle_penetration, 1e-12) << spec << " frame " << f;
      EXPECT_LT(stats.max_speed, 20) << spec << " frame " << f;
    }
  }
}


/// A 1 m square cloth of the default material on an n × n lattice in the plane y = 0, pinned at
/// two adjacent corners, with a small jitter out of the plane so the hinges have work to do.
Cloth pinned_cloth(Index n) {
  TriMesh flat = shapes::lattice(n, n, 1, 1);
  Positions x = flat.positions();
  for (std::size_t i = 0; i < x.size(); ++i) x[i] = Vec3(x[i].x(), 0.01 * std::sin(3.0 * static_cast<Scalar>(i)), x[i].y());
  const TriMesh mesh = TriMesh::create(std::move(x), {flat.topology().faces().begin(), flat.topology().faces().end()});
  Material m;
  m.pins = {0, n};
  Cloth c = make_cloth(mesh, m);
  for (std::size_t i = 0; i < c.state.v.size(); ++i) c.state.v[i] = Vec3(0.1, -0.2 * std::cos(static_cast<Scalar>(i)), 0);
  return c;
}

/// One local/global iteration from the inertial prediction y = x₀ + h v₀ is one exact global
/// solve: the gradient of the step's energy with the springs' directions d_s taken at y,
///   M/h² (x − y) − M g + Σ_s ±k ((x_a − x_b) − d_s) + Σ_hinges wᵢ ((s + c/h) Σⱼ wⱼxⱼ − (c/h) Σⱼ wⱼx₀ⱼ),
/// vanishes at every free particle (pinned ones at y), to 1e-5 of M/h² |x − y|'s scale (the
/// sweeps run over the factor rounded to single precision: measured 3e-6). The same 100 m away
/// from the origin: the solve is for x − y, so its rounding follows the step's displacement,
/// not the coordinates (a single-precision solve for x itself misses by 1e-2 of the scale at
/// the origin, by 2 at 100 m).
/// On a 40 × 40 cloth, whose elimination tree the solve splits between two threads, on 1 and 2.
TEST(Projective, OneIterationSolvesTheGlobalStepExactly) {
  ForceField field;
  field.air_damping = 0;
  const Scalar h = 1.0 / 240;
  for (const auto& [offset, threads] : std::vector<std::pair<Scalar, int>>{{0, 1}, {0, 2}, {100, 1}, {100, 2}}) {
    SCOPED_TRACE("threads " + std::to_string(threads) + ", offset " + std::to_string(offset) + " m");
    Cloth c = pinned_cloth(40);
    for (Vec3& p : c.state.x) p += Vec3(offset, -2 * offset, 0.5 * offset);
    IntegratorOptions options;
    options.projective_iterations = 1;
    options.threads = threads;
    auto integrator = make_integrator(IntegratorKind::Projective, options);
    State s = c.state;
    integrator->step(c.model, field, s, h);
    const std::size_t n = s.x.size();
    const auto mass = c.model.mass();
    std::vector<Vec3> y(n), r(n, Vec3::Zero());
    for (std::size_t i = 0; i < n; ++i) y[i] = c.state.x[i] + h * c.state.v[i];
    Scalar scale = 0;
    for (std::size_t i = 0; i < n; ++i) {
      r[i] = mass[i] / (h * h) * (s.x[i] - y[i]) - mass[i] * field.gravity;
      scale = std::max(scale, (mass[i] / (h * h) * (s.x[i] - y[i])).norm());
    }
    for (const Spring& sp : c.model.springs()) {
      const auto a = static_cast<std::size_t>(sp.a), b = static_cast<std::size_t>(sp.b);
      const Vec3 d = y[a] - y[b];
      const Vec3 f = sp.stiffness * ((s.x[a] - s.x[b]) - sp.rest_length / d.norm() * d);
      r[a] += f;
      r[b] -= f;
    }
    for (const Hinge& hg : c.model.hinges()) {
      Vec3 now = Vec3::Zero(), before = Vec3::Zero();
      for (std::size_t k = 0; k < 4; ++k) {
        now += hg.weight[k] * s.x[static_cast<std::size_t>(hg.vertex[k])];
        before += hg.weight[k] * c.state.x[static_cast<std::size_t>(hg.vertex[k])];
      }
      const Vec3 g = (hg.stiffness + hg.damping / h) * now - (hg.damping / h) * before;
      for (std::size_t k = 0; k < 4; ++k) r[static_cast<std::size_t>(hg.vertex[k])] += hg.weight[k] * g;
    }
    ASSERT_GT(scale, 0);
    Scalar worst = 0;
    for (std::size_t i = 0; i < n; ++i) {
      if (c.model.pinned(static_cast<Index>(i))) {
        EXPECT_EQ(s.x[i], y[i]) << "pinned particle " << i;
      } else {
        EXPECT_LT(r[i].norm(), 1e-5 * scale) << "particle " << i;
        worst = std::max(worst, r[i].norm() / scale);
      }
    }
    std::printf("offset %g m, %d threads: largest residual %.2g of the scale\n", offset, threads, worst);
  }
}

/// The projective solve gives the same bits on 1 and 2 threads, step after step.
TEST(Projective, SameBitsOnOneAndTwoThreads) {
  const Cloth c = pinned_cloth(40);
  const ForceField field;
  std::vector<State> ends;
  for (const int threads : {1, 2}) {
    IntegratorOptions options;
    options.projective_iterations = 5;
    options.projective_rho = 0.8;
    options.threads = threads;
    auto integrator = make_integrator(IntegratorKind::Projective, options);
    State s = c.state;
    for (int k = 0; k < 10; ++k) integrator->step(c.model, field, s, 1.0 / 240);
    ends.push_back(s);
  }
  for (std::size_t i = 0; i < ends[0].x.size(); ++i) {
    ASSERT_EQ(ends[0].x[i], ends[1].x[i]) << "particle " << i;
    ASSERT_EQ(ends[0].v[i], ends[1].v[i]) << "particle " << i;
  }
}

/// The system matrix is factored once and reused while the model (a copy counts as the same),
/// h and the field's linear terms stay; a change of any refactors once.
TEST(Projective, FactorsOnlyWhenTheSystemChanges) {
  const Cloth c = pinned_cloth(8);
  ForceField field;
  auto integrator = make_integrator(IntegratorKind::Projective);
  State s = c.state;
  const auto steps = [&](const Model& model, Scalar h, int count) {
    for (int k = 0; k < count; ++k) integrator->step(model, field, s, h);
    return integrator->factorizations();
  };
  EXPECT_EQ(steps(c.model, 1.0 / 240, 5), 1);
  const Model copy = c.model;
  EXPECT_EQ(steps(copy, 1.0 / 240, 3), 1) << "a copy of the model";
  EXPECT_EQ(steps(c.model, 1.0 / 120, 3), 2) << "another h";
  field.air_damping += 1;
  EXPECT_EQ(steps(c.model, 1.0 / 120, 3), 3) << "another air damping";
  field.drag = DragForce{5, Vec3(0.5, 0.5, 0.5), 100, 1};
  EXPECT_EQ(steps(c.model, 1.0 / 120, 3), 4) << "a drag spring";
  field.drag->target = Vec3(0.5, 0.6, 0.5);
  EXPECT_EQ(steps(c.model, 1.0 / 120, 3), 4) << "the drag's target is on the right-hand side only";
  const Model rebuilt = pinned_cloth(8).model;
  EXPECT_EQ(steps(rebuilt, 1.0 / 120, 3), 5) << "a new model, even with the same contents";
  EXPECT_EQ(make_integrator(IntegratorKind::ImplicitEuler)->factorizations(), 0);
}


/// Particles without springs fall freely, x₁ = x₀ + h v₀ + h² g, and a pinned one stays on
/// its path. The ordering takes the 100,000 one-vertex components of the diagonal system one
/// after the other (it recursed once per component, copying the rest: out of stack, and
/// quadratic).
TEST(Projective, UnconnectedParticlesFallFreely) {
#ifdef CRUMPLE_SANITIZED
  const std::size_t n = 20000;
#else
  const std::size_t n = 100000;
#endif
  std::vector<Scalar> masses(n, 0.01);
  masses[7] = 0;
  const Model model = Model::create(masses, {}, {});
  State s;
  for (std::size_t i = 0; i < n; ++i) {
    s.x.emplace_back(static_cast<Scalar>(i), 0, 0);
    s.v.emplace_back(0, 1, 0);
  }
  const ForceField field;
  const Scalar h = 0.01;
  const State start = s;
  auto integrator = make_integrator(IntegratorKind::Projective);
  integrator->step(model, field, s, h);
  for (std::size_t i = 0; i < n; ++i) {
    const Vec3 expected = start.x[i] + h * start.v[i] + (i == 7 ? Vec3::Zero() : Vec3(h * h * field.gravity));
    ASSERT_LT((s.x[i] - expected).norm(), 1e-12) << "particle " << i;
  }
}

}  // namespace
}  // namespace crumple::sim
