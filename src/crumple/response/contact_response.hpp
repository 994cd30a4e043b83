#pragma once
/// \file
/// Self-collision response by velocity and position correction (thesis Annex B; docs/simulation.md),
/// generalised to unequal masses. Stateless kernels plus a Gauss–Seidel loop over contacts.
///
/// Every contact is turned into a *stencil*: up to four vertices i with signed weights c_i,
/// summing to zero, and a unit normal n, such that the relative quantity across the contact is
/// r = Σ c_i q_i (q = positions or velocities) and its normal part r·n is the gap (positions)
/// or the separating speed (velocities):
///  - vertex–face (P4 against triangle P1 P2 P3 with barycentric w): c = (1, −w1, −w2, −w3),
///    n from the face towards the vertex (Annex B.2);
///  - edge–edge (a = (p1, p2) at s, b = (p1', p2') at t): c = (−(1−s), −s, 1−t, t), n from a
///    towards b (Annex B.1).
///
/// An impulse λ along n changes vertex i by Δq_i = c_i m_i⁻¹ λ n, hence r·n by λ Σ c_i² m_i⁻¹.
/// Velocity correction (inelastic, Annex B.1.1/B.2.1): when v_rel·n < 0 (approaching),
///   λ = −(v_rel·n) / Σ c_i² m_i⁻¹,  so that v_rel·n becomes 0.
/// Position correction (Annex B.1.2/B.2.2): when the gap g = (Σ c_i x_i)·n is below the target
/// thickness h,  μ = (h − g) / Σ c_i² m_i⁻¹,  so that the gap becomes h.
/// With equal masses the denominator is the thesis' (1−s)²+s²+(1−t)²+t² (EE) and
/// 1/m4 + Σ w_i²/m_i (VF). Linear momentum Σ m_i Δv_i = λ n Σ c_i = 0 is conserved; a pinned
/// vertex has m⁻¹ = 0 (infinite mass: it does not move and absorbs momentum).

#include <crumple/core/types.hpp>
#include <crumple/detect/contact.hpp>
#include <crumple/mesh/mesh.hpp>

#include <array>
#include <functional>
#include <span>
#include <vector>

namespace crumple::response {

/// Up to four vertices with signed weights (Σ c_i = 0) and a unit normal; see the file comment.
struct Stencil {
  std::array<Index, 4> vertex{-1, -1, -1, -1};
  std::array<Scalar, 4> weight{0, 0, 0, 0};
  int count = 0;
  Vec3 normal = Vec3::Zero();
  bool edge_edge = false;  ///< EE (vertices a0 a1 b0 b1) or VF (vertex, then the face's corners)
};

/// Moves a stencil to the closest points of its primitives at `positions`: new weights, and the
/// normal of the new closest points, turned to the side of the stencil's current normal (a pair
/// that crossed is still pushed back to the side it came from); kept when the primitives touch
/// (closest points within 1e-9 of the stencil's extent, where their direction is rounding noise).
void refresh_stencil(Stencil& stencil, std::span<const Vec3> positions);
/// `refresh_stencil` of every stencil, bit for bit, in blocks that overlap the stencils' square
/// roots and divisions.
void refresh_stencils(std::span<Stencil> stencils, std::span<const Vec3> positions);

/// Stencil of `vertex` against face `f` at barycentric coordinates `w` (weights 1, −w), with
/// `normal`: the one form shared by proximity contacts and continuous impacts.
Stencil vertex_face_stencil(Index vertex, const Face& f, const Vec3& w, const Vec3& normal);
/// Stencil of edges `a` and `b` at their closest-point parameters `s` and `t`, with `normal`.
Stencil edge_edge_stencil(const Edge& a, const Edge& b, Scalar s, Scalar t, const Vec3& normal);
/// Stencil of a vertex–face contact; `faces` gives the face's corners.
Stencil make_stencil(const VertexFaceContact& contact, std::span<const Face> faces);
/// Stencil of an edge–edge contact.
Stencil make_stencil(const EdgeEdgeContact& contact);
/// Stencils of every VF and EE contact of a set (TT contacts have no response), VF first.
/// Contacts with a zero normal (degenerate geometry) are skipped.
std::vector<Stencil> make_stencils(const ContactSet& contacts, std::span<const Face> faces);

/// Cosines of `drop_flat_neighbours`: a stencil's normal n is "along the cloth" on one side when
/// |n · N| <= `along` (N that side's unit normal: the face's, or the mean of the faces around
/// the vertex or the edge), and the two sides "face alike" when N_a · N_b >= `alike`.
struct FlatNeighbourOptions {
  int rings = 2;          ///< the sides are this many edges apart on the mesh at most (1 or 2)
  Scalar along = 0.5;     ///< n within 30° of both sides' tangent planes
  Scalar alike = 0.866;   ///< the two sides' normals within 30° of each other
  /// Flat pairs whose gap is below this stay (0: none stays by its gap).
  Scalar keep_within = 0;
  int threads = 1;  ///< threads of the test (0 = all); the result does not depend on them
};

/// Removes from `stencils` the pairs of one flat patch of the cloth whose gap is at least
/// `keep_within`: the two sides are at most `rings` edges apart on the mesh (some vertex of one
/// side is within `rings` one-rings of some vertex of the other), their normals face alike, and
/// the pair's normal lies along both (see `FlatNeighbourOptions`), all at `positions`. Such a
/// pair is not two layers closing in: its gap runs within the cloth, joined by at most `rings`
/// edges, so it closes only as fast as those edges shorten, not as fast as a layer falls
/// (docs/simulation.md, "Flat neighbours"). Returns how many were removed; the others keep
/// their order.
std::size_t drop_flat_neighbours(std::vector<Stencil>& stencils, const Topology& topology,
                                 std::span<const Vec3> positions, const FlatNeighbourOptions& options = {});

/// Σ c_i q_i · n over the stencil (the gap for positions, the separating speed for velocities).
Scalar relative_normal(const Stencil& stencil, std::span<const Vec3> q);
/// Σ c_i² m_i⁻¹: the inverse effective mass along the normal (0 when every vertex is pinned).
Scalar inverse_effective_mass(const Stencil& stencil, std::span<const Scalar> inv_mass);

/// Cancels the approaching normal relative velocity of one contact (no-op when separating or
/// when every vertex is pinned). Returns the impulse λ applied (>= 0).
Scalar correct_velocity(const Stencil& stencil, std::span<const Scalar> inv_mass,
                        std::span<Vec3> velocities);
/// Pushes the gap of one contact out to `target` (no-op when the gap is already >= target).
/// Returns μ (>= 0), the positional "impulse".
Scalar correct_position(const Stencil& stencil, std::span<const Scalar> inv_mass,
                        std::span<Vec3> positions, Scalar target);

/// Options of the Gauss–Seidel loop.
struct ResponseOptions {
  Scalar thickness = 0;       ///< position target h (the detection thickness); 0 = no push-out
  int passes = 4;             ///< maximum sweeps over every contact per call (>= 1)
  bool velocity = true;       ///< apply the velocity correction
  bool position = true;       ///< apply the position correction
  /// A contact still "approaches" when v_rel·n < −velocity_tolerance (m/s), and is still
  /// "too close" when the gap < thickness·(1 − position_tolerance).
  Scalar velocity_tolerance = 1e-9;
  Scalar position_tolerance = 1e-6;
};

/// What the loop did.
struct ResponseStats {
  int passes = 0;               ///< sweeps run (the last one found nothing left to do, or hit the limit)
  std::size_t corrections = 0;  ///< velocity plus position corrections applied
  bool converged = false;       ///< the last sweep found no approaching or too-close contact
};

/// Sweeps the stencils in order (Gauss–Seidel: each correction sees the previous ones) until a
/// sweep applies nothing or `options.passes` sweeps ran. `inv_mass`, `positions`, `velocities`
/// have #V entries.
ResponseStats resolve(std::span<const Stencil> stencils, std::span<const Scalar> inv_mass,
                      std::span<Vec3> positions, std::span<Vec3> velocities,
                      const ResponseOptions& options);

/// Options of the proximity response (`resolve_proximity`).
struct ProximityOptions {
  Scalar thickness = 0;  ///< h: contacts with a gap below h are pushed out to h
  Scalar friction = 0;   ///< Coulomb coefficient μ >= 0 between the two sides of a contact
  int passes = 4;        ///< maximum sweeps (>= 1)
  /// A contact is "too close" when its gap < thickness·(1 − position_tolerance).
  Scalar position_tolerance = 1e-6;
  /// ω in (0, 1]: each push-out closes ω of the pair's shortfall h − g (under-relaxed
  /// Gauss–Seidel). 1 = the whole shortfall in one push. Where pairs conflict (a vertex
  /// squeezed between two layers closer than 2h), full pushes alternate between the
  /// constraints' ends, each moving the shared vertex by a whole violation and the last one
  /// winning (the vertex can end past the other layer); ω < 1 damps that cycle towards the
  /// compromise. A lone pair reaches h − (1 − ω)^k (h − g) after k sweeps.
  Scalar relaxation = 1;
};

/// Proximity impulses with friction (Bridson, Fedkiw, Anderson, *Robust treatment of
/// collisions, contact and friction for cloth animation*, SIGGRAPH 2002, §7.1, in the stencil
/// form above). Only contacts whose gap (Σ cᵢxᵢ)·n is below h act — stencils may come from a
/// detection with a larger radius, made once per frame — and each one that does, Gauss–Seidel:
///  1. is pushed out to the gap h (μ = ω (h − g) / Σ cᵢ² mᵢ⁻¹, ω = `relaxation`; with ω = 1
///     as `correct_position`);
///  2. loses its approaching normal relative velocity (λ = −v_rel·n / Σ cᵢ² mᵢ⁻¹ when < 0);
///  3. has its tangential relative velocity v_t reduced by Coulomb friction: an impulse
///     λ_t = min(μ λ, |v_t| / Σ cᵢ² mᵢ⁻¹) against v_t, so sliding stops when |v_t| ≤ μ λ Σ cᵢ² mᵢ⁻¹.
/// Momentum is conserved (Σ cᵢ = 0). Sweeps until none acts or `passes` ran.
ResponseStats resolve_proximity(std::span<const Stencil> stencils, std::span<const Scalar> inv_mass,
                                std::span<Vec3> positions, std::span<Vec3> velocities,
                                const ProximityOptions& options);

/// Options of the contact forces of a projective step (`update_contact_forces`).
struct ContactForceOptions {
  Scalar thickness = 0;    ///< h: a pair's force grows while its gap is below h, shrinks above
  Scalar relaxation = 0.5; ///< ω in (0, 1]: the share of the diagonal estimate each update takes
};
/// Buffers of `update_contact_forces`, kept by its caller between calls (it runs at every
/// iteration of every step; each call sizes and clears them, so what they hold between calls
/// does not matter).
struct ContactForceScratch {
  std::vector<Scalar> change, asked;  ///< per stencil: its Δλ, and the gap change it asks for
  std::vector<char> acting;           ///< per stencil
  std::vector<int> count;             ///< per vertex: nᵢ
  std::vector<Vec3> proposed, moved;  ///< per vertex: the proposed forces, their displacements
};
/// The contacts' part of a projective step's local step (docs/simulation.md, "Contacts in the
/// projective step"): one update of each stencil's multiplier λ ≥ 0 — the force λ cᵢ n on its
/// vertex i — at the iterate `x`, then the forces into `force` (added; #V entries). A stencil
/// acts when its gap g = (Σ cᵢxᵢ)·n is below h or its λ is positive. Its proposed change is
/// Δλ = ω (h − g) / Σ cᵢ² nᵢ / Dᵢ (clamped so that λ stays ≥ 0), with Dᵢ the system's diagonal
/// at vertex i (`diagonal`, 0 for a pinned vertex, which takes no force) and nᵢ the number of
/// acting stencils at vertex i: what would close ω of the shortfall if the global step moved
/// each vertex by its own force over its diagonal. That estimate is low for forces that push a
/// whole patch one way (the springs do not resist a patch's translation: up to 1 + 4 (ωh)²
/// times as far), so the proposed changes' response is measured — `solve` gives the global
/// step's displacements A⁻¹ f for their forces f — and each Δλ whose pair would move by more
/// than it asked is scaled down to what it asked. So λ grows while a pair stays closer than h,
/// shrinks when it is farther and reaches 0 when it separates. `lambda` has one entry per
/// stencil, kept by the caller between calls (the warm start of the next iteration and step).
void update_contact_forces(std::span<const Stencil> stencils, std::span<const Vec3> x,
                           std::span<const Scalar> diagonal,
                           const std::function<void(std::span<const Vec3>, std::span<Vec3>)>& solve,
                           const ContactForceOptions& options, std::span<Scalar> lambda, std::span<Vec3> force,
                           ContactForceScratch& scratch);
}  // namespace crumple::response
