// sim::fit_time_step: the rule shared by the CLI's `simulate` and the Python `Simulation`.
#include <crumple/sim/scene.hpp>
#include <crumple/sim/time_step.hpp>

#include <gtest/gtest.h>

#include <cmath>

namespace crumple::sim {
namespace {

TEST(TimeStep, StableSplitKeepsTheFrameLength) {
  const auto [dt, substeps] = stable_split(0.01, 0.001);
  EXPECT_EQ(substeps, 12);  // ceil(0.01 / 0.0009)
  EXPECT_DOUBLE_EQ(dt * substeps, 0.01);
  EXPECT_LE(dt, 0.9 * 0.001);
  EXPECT_EQ(stable_split(0.01, 1.0).second, 1);
}

TEST(TimeStep, SceneStepSplitUserStepKeptImplicitStable) {
  const Scene scene = make_scene(SceneSpec::parse("cloth-on-sphere:n=6"), 1);
  Settings settings = scene.settings;
  settings.integrator = IntegratorKind::SymplecticEuler;
  const Settings given = settings;
  TimeStepFit fit = fit_time_step(settings, scene.model, scene.field, scene.state.x, false);
  ASSERT_EQ(fit.action, StepFit::Split);
  EXPECT_EQ(fit.stable_dt, stable_time_step(scene.model, scene.field, scene.state.x, IntegratorKind::SymplecticEuler));
  EXPECT_GT(given.dt, fit.stable_dt);
  EXPECT_LT(settings.dt, fit.stable_dt);
  EXPECT_GT(settings.substeps, given.substeps);
  EXPECT_EQ(settings.dt, fit.dt);
  EXPECT_EQ(settings.substeps, fit.substeps);
  EXPECT_NEAR(settings.dt * settings.substeps, given.dt * given.substeps, 1e-15);
  EXPECT_EQ(fit.given_dt, given.dt);
  EXPECT_EQ(fit.given_substeps, given.substeps);

  settings = given;  // chosen by the user: kept, the split only suggested
  fit = fit_time_step(settings, scene.model, scene.field, scene.state.x, true);
  EXPECT_EQ(fit.action, StepFit::Kept);
  EXPECT_EQ(settings.dt, given.dt);
  EXPECT_EQ(settings.substeps, given.substeps);
  EXPECT_LT(fit.dt, fit.stable_dt);

  settings = given;  // a split costing more than 100 times the steps: kept
  settings.dt = 1000 * fit.stable_dt;
  settings.substeps = 1;
  EXPECT_EQ(fit_time_step(settings, scene.model, scene.field, scene.state.x, false).action, StepFit::Kept);
  EXPECT_EQ(settings.substeps, 1);

  settings = given;
  settings.integrator = IntegratorKind::ImplicitEuler;
  fit = fit_time_step(settings, scene.model, scene.field, scene.state.x, false);
  EXPECT_EQ(fit.action, StepFit::Stable);
  EXPECT_TRUE(std::isinf(fit.stable_dt));
  EXPECT_EQ(settings.dt, given.dt);
}

}  // namespace
}  // namespace crumple::sim
