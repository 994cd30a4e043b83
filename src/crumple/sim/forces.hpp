#pragma once
/// \file
/// Forces on a mass–spring model: gravity, springs (Hooke + damping along the spring, see
/// `Spring`), bending hinges (`Hinge`), air (viscous) damping and a "mouse spring" dragging one particle towards a point.
/// Pure functions of (model, field, x, v); pinned particles receive forces but never move.

#include <crumple/sim/mass_spring.hpp>

#include <Eigen/SparseCore>

#include <optional>
#include <span>
#include <vector>

namespace crumple::sim {

/// Drags particle `vertex` towards `target`: f = k (target − x) − c v.
struct DragForce {
  Index vertex = -1;
  Vec3 target = Vec3::Zero();
  Scalar stiffness = 100;  ///< k, N/m
  Scalar damping = 1;      ///< c, N·s/m
};

/// The external force field of a scene.
struct ForceField {
  Vec3 gravity = Vec3(0, -9.81, 0);  ///< m/s²; force m g on every particle
  Scalar air_damping = 0;            ///< 1/s; force −air_damping · m · v on every particle
  std::optional<DragForce> drag;
};

/// Total force on every particle at (x, v): `forces` is resized to #V and overwritten (N).
void compute_forces(const Model& model, const ForceField& field, std::span<const Vec3> x,
                    std::span<const Vec3> v, std::vector<Vec3>& forces);

/// Jacobians of the forces, 3#V × 3#V, particle i in rows/columns 3i..3i+2:
/// ∂f/∂x (springs, hinges and the drag) and ∂f/∂v (spring and hinge damping, air damping, drag
/// damping). A hinge adds the constant −s w wᵀ ⊗ I₃ (and −c w wᵀ ⊗ I₃ to ∂f/∂v).
/// The spring term is −k [ d̂d̂ᵀ + max(0, 1 − L/l) (I − d̂d̂ᵀ) ], the transverse part clamped at 0
/// for compressed springs so that M − h ∂f/∂v − h² ∂f/∂x stays symmetric positive definite
/// (Baraff & Witkin 1998; Choi & Ko 2002). Both matrices are symmetric.
struct ForceJacobians {
  Eigen::SparseMatrix<Scalar> dfdx;
  Eigen::SparseMatrix<Scalar> dfdv;
};
ForceJacobians compute_force_jacobians(const Model& model, const ForceField& field,
                                       std::span<const Vec3> x);

/// The 3×3 blocks of one spring: ∂f_a/∂x_a = `dx` (= ∂f_b/∂x_b = −∂f_a/∂x_b) and
/// ∂f_a/∂v_a = `dv`, as above; `damping` is the spring's coefficient c.
struct SpringBlocks {
  Eigen::Matrix<Scalar, 3, 3> dx;
  Eigen::Matrix<Scalar, 3, 3> dv;
};
SpringBlocks spring_blocks(const Spring& spring, Scalar damping, const Vec3& xa, const Vec3& xb);

/// Energies (J): kinetic ½ Σ m v², spring ½ Σ k (l − L)², bending ½ Σ s |Σ wᵢ xᵢ|² (hinges),
/// gravity −Σ m g·x (free particles), drag ½ k |target − x|².
struct Energy {
  Scalar kinetic = 0;
  Scalar spring = 0;
  Scalar gravity = 0;
  Scalar drag = 0;
  Scalar bending = 0;
  Scalar total() const { return kinetic + spring + gravity + drag + bending; }
};
Energy compute_energy(const Model& model, const ForceField& field, const State& state);

/// Linear momentum Σ m v of the free particles (kg·m/s).
Vec3 linear_momentum(const Model& model, std::span<const Vec3> v);

/// The longest spring at positions `x` (#V), as a multiple of its rest length: the largest
/// |x_a − x_b| / L over the springs with L > 0 (0 without such springs). The stretch that the
/// position corrections leave behind.
Scalar longest_spring_ratio(const Model& model, std::span<const Vec3> x);

}  // namespace crumple::sim
