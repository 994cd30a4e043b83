#pragma once
/// \file
/// Mass–spring model (thesis Annex A; docs/simulation.md): particles with mass, position and velocity
/// linked by springs with stiffness, damping ratio and rest length. A mass of 0 pins the
/// particle (infinite mass: forces and collision response never move it; the scene may still
/// drive it kinematically). The triangles of the surface are kept for collision detection.

#include <crumple/core/types.hpp>
#include <crumple/mesh/mesh.hpp>

#include <memory>
#include <span>
#include <vector>

namespace crumple::sim {

/// A spring between two particles. Force on a (b gets the opposite), with d = x_a − x_b,
/// l = |d|, d̂ = d / l:  f_a = −[ k (l − L) + c (v_a − v_b)·d̂ ] d̂,  with the damping
/// coefficient c = 2 ζ √(k μ) from the damping ratio ζ and the reduced mass
/// μ = m_a m_b / (m_a + m_b) (μ = the free particle's mass when the other is pinned), so that
/// ζ = 1 damps the two-body oscillation critically.
struct Spring {
  Index a = -1;
  Index b = -1;
  Scalar stiffness = 0;      ///< k, N/m
  Scalar damping_ratio = 0;  ///< ζ, dimensionless
  Scalar rest_length = 0;    ///< L, m
};

/// Positions and velocities of every particle (#V each), and the simulated time.
struct State {
  Positions x;
  Positions v;
  Scalar time = 0;  ///< s
};

/// The immutable part of a mass–spring system.
class Model {
 public:
  /// Validates and builds. `masses` (#V, >= 0, 0 = pinned), springs with ids in range, no
  /// spring from a particle to itself, finite non-negative parameters; `faces` (may be empty)
  /// with ids in range. Throws `InputError` naming the element otherwise.
  static Model create(std::vector<Scalar> masses, std::vector<Spring> springs,
                      std::vector<Face> faces);

  Index num_particles() const { return static_cast<Index>(mass_.size()); }
  std::span<const Scalar> mass() const { return mass_; }
  /// 1/m, 0 for pinned particles.
  std::span<const Scalar> inv_mass() const { return inv_mass_; }
  bool pinned(Index i) const { return inv_mass_[static_cast<std::size_t>(i)] == 0; }
  std::span<const Spring> springs() const { return springs_; }
  /// Damping coefficient c of each spring (see `Spring`), N·s/m.
  std::span<const Scalar> damping() const { return damping_; }
  /// Triangles for collision detection (topology built once).
  const Topology& topology() const { return *topology_; }
  std::shared_ptr<const Topology> topology_ptr() const { return topology_; }
  /// Total mass of the free particles.
  Scalar free_mass() const;

 private:
  std::vector<Scalar> mass_, inv_mass_, damping_;
  std::vector<Spring> springs_;
  std::shared_ptr<const Topology> topology_;
};

/// Material of a cloth built from a triangle mesh.
struct ClothParams {
  Scalar density = 0.1;         ///< kg/m², lumped: each vertex gets 1/3 of its faces' mass
  Scalar stiffness = 1000;      ///< N/m, on every mesh edge (structural springs)
  Scalar damping_ratio = 0.05;  ///< ζ of the structural springs
  /// N/m of the bending springs across every interior edge (between the two vertices opposite
  /// the edge); 0 = no bending springs.
  Scalar bending_stiffness = 0;
  Scalar bending_damping_ratio = 0.05;
  std::vector<Index> pins;  ///< vertices with mass 0
};

/// Structural springs on every mesh edge (in mesh edge order, rest length = the current edge
/// length) followed by the bending springs, one per edge with exactly two faces.
std::vector<Spring> cloth_springs(const Topology& topology, PositionsView positions,
                                  const ClothParams& params);

/// A cloth on `mesh` at rest: lumped masses from the area, springs from `cloth_springs`,
/// zero velocities. Throws `InputError` for a pin out of range or a vertex with zero mass
/// that is not pinned (an isolated vertex or zero-area faces only).
struct Cloth {
  Model model;
  State state;
};
Cloth make_cloth(const TriMesh& mesh, const ClothParams& params);

}  // namespace crumple::sim
