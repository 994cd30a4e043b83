#pragma once
/// \file
/// Mass–spring model (thesis Annex A; docs/simulation.md): particles with mass, position and velocity
/// linked by springs with stiffness, damping ratio and rest length. A mass of 0 pins the
/// particle (infinite mass: forces and collision response never move it; the scene may still
/// drive it kinematically). The triangles of the surface are kept for collision detection.

#include <crumple/core/types.hpp>
#include <crumple/mesh/mesh.hpp>

#include <array>
#include <cstdint>
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

/// A bending hinge: the quadratic bending energy of one interior edge (the "isometric bending
/// model", Bergou, Wardetzky, Harmon, Zorin, Grinspun, *A quadratic bending model for
/// inextensible surfaces*, SGP 2006), exact for a flat rest state:
///   E = ½ s |Σᵢ wᵢ xᵢ|²,   f_i = −s wᵢ (Σⱼ wⱼ xⱼ) − c wᵢ (Σⱼ wⱼ vⱼ),
/// over the edge's ends (vertex[0], vertex[1]) and the two opposite vertices (vertex[2],
/// vertex[3]). The weights sum to 0 and annihilate every affine map of the flat rest positions,
/// so in-plane motion and rigid motion cost nothing; bending the hinge by a small angle θ gives
/// |Σ wᵢ xᵢ| ≈ θ. The Hessian s w wᵀ ⊗ I₃ is constant.
struct Hinge {
  std::array<Index, 4> vertex{-1, -1, -1, -1};
  std::array<Scalar, 4> weight{0, 0, 0, 0};  ///< 1/m
  Scalar stiffness = 0;  ///< s, J (N·m)
  Scalar damping = 0;    ///< c, J·s
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
  /// `hinges` (may be empty): ids in range and distinct, finite weights, finite non-negative
  /// stiffness and damping.
  static Model create(std::vector<Scalar> masses, std::vector<Spring> springs,
                      std::vector<Face> faces, std::vector<Hinge> hinges = {});

  Index num_particles() const { return static_cast<Index>(mass_.size()); }
  std::span<const Scalar> mass() const { return mass_; }
  /// 1/m, 0 for pinned particles.
  std::span<const Scalar> inv_mass() const { return inv_mass_; }
  bool pinned(Index i) const { return inv_mass_[static_cast<std::size_t>(i)] == 0; }
  std::span<const Spring> springs() const { return springs_; }
  /// Damping coefficient c of each spring (see `Spring`), N·s/m.
  std::span<const Scalar> damping() const { return damping_; }
  /// Bending hinges (empty for the thesis' spring-only models and X3D `MassSpring` files).
  std::span<const Hinge> hinges() const { return hinges_; }
  /// The same model with `hinges` instead of its own (validated as in `create`); used when a
  /// model read from a `MassSpring` file, which has no hinges, resumes a scene that has them.
  Model with_hinges(std::vector<Hinge> hinges) const;
  /// Triangles for collision detection (topology built once).
  const Topology& topology() const { return *topology_; }
  std::shared_ptr<const Topology> topology_ptr() const { return topology_; }
  /// Total mass of the free particles.
  Scalar free_mass() const;
  /// Names the model's contents: copies share it, every model made by `create` or
  /// `with_hinges` in this process gets a new one (0: a default-constructed, empty model). A
  /// solver keeps what it derived from a model (a factored matrix) while it is given the same.
  std::uint64_t revision() const { return revision_; }

 private:
  std::uint64_t revision_ = 0;
  std::vector<Scalar> mass_, inv_mass_, damping_;
  std::vector<Spring> springs_;
  std::vector<Hinge> hinges_;
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

/// A cloth material given per unit area and length, so that the same material on a finer mesh of
/// the same surface behaves alike (docs/simulation.md, "Material"). On a mesh with face areas
/// A_f, each edge e gets the area A_e = Σ_{f ∋ e} A_f / 3 (the faces' areas split between their
/// three edges; Σ_e A_e = total area), and:
///  - a structural spring on e, k = stretch · A_e / L_e²;
///  - with shear > 0, a spring between the two vertices opposite each interior edge (the quad's
///    other diagonal on a lattice), k = shear · A_e / L², L its rest length;
///  - with bending > 0, a `Hinge` on each interior edge, s = 3 · bending · A_e / d², d the mean
///    of the opposite vertices' distances to the edge's line (a cylinder of curvature κ across
///    the edge stores 3 × ½ bending κ² A_e in it; a hinge feels only the curvature across its own
///    edge, and the factor 3 makes a lattice rolled onto a cylinder, along either side, store the
///    plate's energy ½ bending κ² A to within the O(1/n) boundary strip, tested);
///  - damping as a Kelvin–Voigt relaxation time τ: every spring's damping coefficient is τ k
///    (stored as the damping ratio τ k / (2 √(k μ))), every hinge's is τ s.
/// A uniform isotropic stretch by a small strain ε stores ½ (stretch + shear) ε² A in the
/// springs whatever the mesh; masses are lumped from `density` as in `make_cloth`. The bending
/// model's rest shape is flat: on a curved mesh the hinges pull it flat.
struct Material {
  Scalar density = 0.1;   ///< kg/m²
  Scalar stretch = 400;   ///< N/m (in-plane stiffness per unit width)
  /// N/m. On a triangle mesh the structural springs already resist shear; these extra springs
  /// also shorten when their hinge folds, so they stiffen folding too (more on coarse meshes):
  /// 0 by default.
  Scalar shear = 0;
  Scalar bending = 1e-4;  ///< N·m (bending rigidity D)
  Scalar damping = 0.01;  ///< s (τ)
  std::vector<Index> pins;  ///< vertices with mass 0
};

/// A cloth of `material` on `mesh` at rest (zero velocities); the same errors as `make_cloth`,
/// and `InputError` for a negative or non-finite material parameter or density <= 0.
Cloth make_cloth(const TriMesh& mesh, const Material& material);

}  // namespace crumple::sim
