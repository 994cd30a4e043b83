// The projective step's settling tolerance (`IntegratorOptions::projective_tolerance`) and the
// coiling ribbon it keeps from diverging (docs/simulation.md, "Energy under contact").
#include <crumple/core/error.hpp>
#include <crumple/mesh/shapes.hpp>
#include <crumple/sim/scene.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>

namespace crumple::sim {
namespace {

/// A 1 m square of the default material on an n × n lattice in the plane y = 0, pinned at two
/// adjacent corners, stretched by 30% along x (the springs' rest lengths are the unstretched
/// ones): a state whose strain a position correction could have stored.
Cloth stretched_cloth(Index n) {
  TriMesh flat = shapes::lattice(n, n, 1, 1);
  Positions x = flat.positions();
  for (Vec3& p : x) p = Vec3(p.x(), 0, p.y());
  const TriMesh mesh = TriMesh::create(x, {flat.topology().faces().begin(), flat.topology().faces().end()});
  Material m;
  m.pins = {0, n};
  Cloth c = make_cloth(mesh, m);
  for (Vec3& p : c.state.x) p.x() *= 1.3;
  return c;
}

State run(const Cloth& c, const IntegratorOptions& options, int steps, int* iterations = nullptr,
          bool gravity = true) {
  auto integrator = make_integrator(IntegratorKind::Projective, options);
  ForceField field;
  if (!gravity) field.gravity = Vec3::Zero();
  State s = c.state;
  int total = 0;
  for (int k = 0; k < steps; ++k) {
    integrator->step(c.model, field, s, 1.0 / 240);
    total += integrator->last_iterations();
  }
  if (iterations) *iterations = total;
  return s;
}

Scalar largest_difference(const State& a, const State& b) {
  Scalar d = 0;
  for (std::size_t i = 0; i < a.x.size(); ++i) d = std::max(d, (a.x[i] - b.x[i]).norm());
  return d;
}

/// With a tolerance the step iterates past `projective_iterations` while the strained cloth
/// relaxes, stops once an iteration moves no particle more than the tolerance, and lands
/// nearer the converged backward Euler step (200 iterations) than the fixed 5 iterations do;
/// the same bits on one and two threads.
TEST(Settle, IteratesUntilTheParticlesSettle) {
  const Cloth c = stretched_cloth(16);
  IntegratorOptions fixed;
  fixed.projective_iterations = 5;
  fixed.projective_rho = 0.8;
  IntegratorOptions converged = fixed;
  converged.projective_iterations = 200;
  IntegratorOptions settle = fixed;
  settle.projective_tolerance = 1e-5;
  settle.projective_max_iterations = 100;
  int fixed_iterations = 0, settle_iterations = 0;
  const State reference = run(c, converged, 1);
  const State few = run(c, fixed, 1, &fixed_iterations);
  const State settled = run(c, settle, 1, &settle_iterations);
  std::printf("iterations: fixed %d, settled %d; distance to the converged step: %.3g vs %.3g m\n",
              fixed_iterations, settle_iterations, largest_difference(few, reference),
              largest_difference(settled, reference));
  EXPECT_EQ(fixed_iterations, 5);
  EXPECT_GT(settle_iterations, 5);
  EXPECT_LT(settle_iterations, 100);
  EXPECT_LT(largest_difference(settled, reference), 0.1 * largest_difference(few, reference));

  // At rest (no strain, no gravity, no motion) the first iterations already settle.
  Cloth rest = stretched_cloth(8);
  for (Vec3& p : rest.state.x) p.x() /= 1.3;
  int rest_iterations = 0;
  run(rest, settle, 3, &rest_iterations, false);
  EXPECT_EQ(rest_iterations, 3 * 5);

  std::vector<State> ends;
  for (const int threads : {1, 2}) {
    IntegratorOptions o = settle;
    o.threads = threads;
    ends.push_back(run(c, o, 4));
  }
  for (std::size_t i = 0; i < ends[0].x.size(); ++i) {
    ASSERT_EQ(ends[0].x[i], ends[1].x[i]) << "particle " << i;
    ASSERT_EQ(ends[0].v[i], ends[1].v[i]) << "particle " << i;
  }
}

TEST(Settle, RejectsBadOptions) {
  IntegratorOptions o;
  o.projective_tolerance = -1;
  EXPECT_ANY_THROW(make_integrator(IntegratorKind::Projective, o));
  o.projective_tolerance = 1e-4;
  o.projective_iterations = 10;
  o.projective_max_iterations = 5;
  EXPECT_ANY_THROW(make_integrator(IntegratorKind::Projective, o));
  EXPECT_THROW(make_scene(SceneSpec::parse("twisted-ribbon:settle=-1"), 1), InputError);
}

/// The twisted ribbon (48 × 3, 6 turns, ends brought to 0.3 of the length apart) coils onto
/// itself from frame ~150. With the fixed 5 iterations per step (`settle=0`) it heated up under
/// its contacts and diverged at frame 224 (positions stored by the contact response and the
/// fail-safe given back as motion); settled, it stays slow and intersection-free through
/// frame 260.
TEST(Settle, TwistedRibbonCoilsWithoutDiverging) {
  Scene s = make_scene(SceneSpec::parse("twisted-ribbon"), 1);
  ASSERT_GT(s.settings.integrator_options.projective_tolerance, 0);
  Settings settings = s.settings;
  settings.detector.threads = 1;
  Simulation sim(std::move(s.model), std::move(s.state), s.field, std::move(s.obstacles), std::move(s.kinematics),
                 settings);
  Scalar fastest = 0;
  for (int f = 1; f <= 260; ++f) {
    FrameStats stats;
    ASSERT_NO_THROW(stats = sim.advance_frame()) << "frame " << f;
    fastest = std::max(fastest, stats.max_speed);
    ASSERT_LT(stats.max_speed, 5) << "frame " << f;
    ASSERT_EQ(stats.intersecting_pairs, 0) << "frame " << f;
  }
  std::printf("fastest particle over 260 frames: %.3g m/s\n", fastest);
}

}  // namespace
}  // namespace crumple::sim
