#pragma once
/// \file
/// Fitting a frame's steps to an explicit integrator's stable range: the one rule that the CLI's
/// `simulate` and the Python `Simulation` both apply to a scene's time step.

#include <crumple/sim/integrator.hpp>
#include <crumple/sim/simulation.hpp>

#include <span>
#include <utility>

namespace crumple::sim {

/// `frame_time` split into equal steps of at most 0.9 × `stable_dt`: (dt, substeps), with
/// dt × substeps = frame_time and substeps in 1..10⁹.
std::pair<Scalar, int> stable_split(Scalar frame_time, Scalar stable_dt);

/// What `fit_time_step` did with a settings' step.
enum class StepFit {
  Stable,  ///< dt within the stable range (always so for implicit Euler and projective)
  Split,   ///< the scene's own dt split into stable substeps of the same frame length
  Kept,    ///< dt beyond the stable range kept as given: the run will likely diverge
};

struct TimeStepFit {
  StepFit action = StepFit::Stable;
  Scalar stable_dt = 0;  ///< `stable_time_step(model, field, x, integrator)`
  Scalar given_dt = 0;   ///< the step before the fit
  int given_substeps = 1;
  /// A stable split of the same frame length: what `Split` applied, what `Kept` suggests;
  /// the given step when `Stable`.
  Scalar dt = 0;
  int substeps = 1;
};

/// The rule: a step beyond the integrator's stable range (`stable_time_step`) is split into
/// stable substeps of the same frame length (`settings.dt` and `settings.substeps` changed) when
/// it is the scene's own step (`user_step` false: neither dt nor substeps chosen by the user)
/// and the split costs at most 100 times the steps; otherwise it is kept as given. The caller
/// says which (the library never prints).
TimeStepFit fit_time_step(Settings& settings, const Model& model, const ForceField& field,
                          std::span<const Vec3> x, bool user_step);

}  // namespace crumple::sim
