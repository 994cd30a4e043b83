#include <crumple/sim/time_step.hpp>

#include <cmath>
#include <tuple>

namespace crumple::sim {

std::pair<Scalar, int> stable_split(Scalar frame_time, Scalar stable_dt) {
  const double n = std::ceil(frame_time / (0.9 * stable_dt));
  const int substeps = n < 1 ? 1 : n > 1e9 ? 1000000000 : static_cast<int>(n);
  return {frame_time / substeps, substeps};
}

TimeStepFit fit_time_step(Settings& settings, const Model& model, const ForceField& field,
                          std::span<const Vec3> x, bool user_step) {
  TimeStepFit fit;
  fit.stable_dt = stable_time_step(model, field, x, settings.integrator);
  fit.given_dt = fit.dt = settings.dt;
  fit.given_substeps = fit.substeps = settings.substeps;
  if (!(settings.dt > fit.stable_dt)) return fit;
  std::tie(fit.dt, fit.substeps) = stable_split(settings.dt * settings.substeps, fit.stable_dt);
  if (!user_step && fit.substeps <= 100 * settings.substeps) {
    fit.action = StepFit::Split;
    settings.dt = fit.dt;
    settings.substeps = fit.substeps;
  } else {
    fit.action = StepFit::Kept;
  }
  return fit;
}

}  // namespace crumple::sim
