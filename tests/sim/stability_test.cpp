// The stable step estimate and the divergence check of the simulation loop (issue 45).
#include <crumple/sim/scene.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

namespace crumple::sim {
namespace {

/// One free particle of mass m on a spring k to a pinned one, damping ratio ζ: ω = √(k/m).
Model single_spring(Scalar k, Scalar m, Scalar zeta) {
  return Model::create({0, m}, {{0, 1, k, zeta, 1}}, {});
}

TEST(Stability, StableStepFollowsEachSchemesBound) {
  const Model undamped = single_spring(100, 1, 0);  // ω = 10
  EXPECT_NEAR(stable_time_step(undamped, IntegratorKind::SymplecticEuler), 0.2, 1e-12);
  EXPECT_NEAR(stable_time_step(undamped, IntegratorKind::Rk4), 0.278, 1e-12);
  EXPECT_EQ(stable_time_step(undamped, IntegratorKind::ExplicitEuler), 0)
      << "explicit Euler gains energy on an undamped spring at any step";
  EXPECT_TRUE(std::isinf(stable_time_step(undamped, IntegratorKind::ImplicitEuler)));
  EXPECT_NEAR(stable_time_step(single_spring(100, 1, 0.1), IntegratorKind::ExplicitEuler), 0.02,
              1e-12);
  // Two free particles (mass 1 each): the Gershgorin bound 2k/m, ω = √200.
  const Model pair = Model::create({1, 1}, {{0, 1, 100, 0, 1}}, {});
  EXPECT_NEAR(stable_time_step(pair, IntegratorKind::SymplecticEuler), 2 / std::sqrt(200.0), 1e-12);
  EXPECT_TRUE(std::isinf(stable_time_step(Model::create({1}, {}, {}), IntegratorKind::Rk4)));
}

// The estimate separates the steps that diverge from those that do not on a real scene.
TEST(Stability, EstimateSeparatesStableFromUnstableSteps) {
  for (const IntegratorKind kind : {IntegratorKind::SymplecticEuler, IntegratorKind::Rk4}) {
    Scene scene = make_scene(SceneSpec::parse("cloth-on-sphere:n=6"), 1);
    const Scalar h = stable_time_step(scene.model, kind);
    ASSERT_TRUE(h > 0 && std::isfinite(h));
    for (const auto& [dt, diverges] : {std::pair{0.8 * h, false}, std::pair{4 * h, true}}) {
      Scene s = make_scene(SceneSpec::parse("cloth-on-sphere:n=6"), 1);
      Settings settings = s.settings;
      settings.integrator = kind;
      settings.dt = dt;
      settings.substeps = 5;
      settings.detector.threads = 1;
      Simulation sim(std::move(s.model), std::move(s.state), s.field, std::move(s.obstacles),
                     std::move(s.kinematics), settings);
      bool diverged = false;
      try {
        for (int f = 0; f < 60; ++f) sim.advance_frame();
      } catch (const DivergenceError&) {
        diverged = true;
      }
      EXPECT_EQ(diverged, diverges) << to_string(kind) << " dt " << dt << " (estimate " << h << ")";
    }
  }
}

// A diverging step throws with the frame and step, and leaves the frame's starting state:
// finite, resumable.
TEST(Stability, DivergenceRestoresTheLastGoodFrame) {
  Scene s = make_scene(SceneSpec::parse("cloth-on-sphere:n=6"), 1);
  Settings settings = s.settings;
  settings.integrator = IntegratorKind::ExplicitEuler;
  settings.dt = 0.01;
  settings.substeps = 1;
  settings.detector.threads = 1;
  Simulation sim(std::move(s.model), std::move(s.state), s.field, std::move(s.obstacles),
                 std::move(s.kinematics), settings);
  State last_good = sim.state();
  std::int64_t frames = 0;
  try {
    for (; frames < 100; ++frames) {
      last_good = sim.state();
      const FrameStats stats = sim.advance_frame();
      EXPECT_TRUE(std::isfinite(stats.energy) && std::isfinite(stats.max_speed));
      EXPECT_TRUE(stats.bounds.min.allFinite() && stats.bounds.max.allFinite());
    }
    FAIL() << "explicit Euler at 0.01 s must diverge on this scene";
  } catch (const DivergenceError& e) {
    EXPECT_EQ(e.frame(), frames + 1);
    EXPECT_EQ(e.step(), 1);
    EXPECT_NE(std::string(e.what()).find("diverged at frame " + std::to_string(frames + 1)),
              std::string::npos)
        << e.what();
  }
  EXPECT_EQ(sim.frame(), frames);
  EXPECT_EQ(sim.state().x, last_good.x);
  EXPECT_EQ(sim.state().v, last_good.v);
  EXPECT_EQ(sim.state().time, last_good.time);
}

TEST(Stability, NonFiniteInitialStateIsRejected) {
  Scene s = make_scene(SceneSpec::parse("hanging-cloth:nx=3,ny=3"), 1);
  s.state.x[4].x() = std::numeric_limits<Scalar>::quiet_NaN();
  EXPECT_THROW(Simulation(std::move(s.model), std::move(s.state), s.field, std::move(s.obstacles),
                          std::move(s.kinematics), s.settings),
               InputError);
}

}  // namespace
}  // namespace crumple::sim
