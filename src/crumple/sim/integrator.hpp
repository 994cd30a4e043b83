#pragma once
/// \file
/// Time integrators behind one interface (thesis Annex A.2; docs/simulation.md). Each advances
/// q = (x, v) by one step h with the forces of `forces.hpp`; a = M⁻¹ f, zero for pinned
/// particles, whose velocity is therefore kept (a kinematic pin with velocity u moves by h u).
///
///  - explicit Euler:  x₁ = x₀ + h v₀,  v₁ = v₀ + h a(x₀, v₀). First order, gains energy;
///    unstable once h ω > ~0 on undamped springs (ω = √(k/m)).
///  - symplectic (semi-implicit) Euler:  v₁ = v₀ + h a(x₀, v₀),  x₁ = x₀ + h v₁. First order,
///    energy bounded for h ω < 2.
///  - RK4: classical fourth-order Runge–Kutta on (x, v). Accurate, 4 force evaluations,
///    unstable for h ω > ~2.8.
///  - implicit (backward) Euler, one linearised Newton step (Baraff & Witkin, "Large steps in
///    cloth simulation", SIGGRAPH 1998):  (M − h ∂f/∂v − h² ∂f/∂x) Δv = h (f₀ + h ∂f/∂x v₀),
///    v₁ = v₀ + Δv,  x₁ = x₀ + h v₁, solved by preconditioned conjugate gradient on the sparse
///    system (`CgPreconditioner`: by default a prefactored constant matrix plus A's 3×3 diagonal
///    blocks; Jacobi on request), to a relative residual of `cg_tolerance` either way, pinned
///    rows and columns replaced by the identity (Δv = 0). Unconditionally stable, dissipative.
///  - projective dynamics (Liu, Bargteil, O'Brien, Kavan, *Fast simulation of mass-spring
///    systems*, SIGGRAPH Asia 2013; Bouaziz et al., *Projective dynamics*, SIGGRAPH 2014):
///    backward Euler as the minimisation of
///      ½h⁻² |x − x₀ − h v₀|²_M + Σ_springs ½ k |x_a − x_b − d_s|² + Σ_hinges ½ (s + c/h) |Σ wᵢxᵢ|²
///      − (c/h)(Σ wᵢxᵢ)·(Σ wᵢx₀ᵢ) + air, drag and gravity terms,
///    alternating a local step (d_s = L (x_a − x_b)/|x_a − x_b|, the spring's rest-length
///    projection) and a global step, a linear solve with the constant matrix
///    M/h² + air M/h + Σ k GᵀG + Σ (s + c/h) w wᵀ (+ drag), one matrix for x, y and z, factored
///    once by sparse Cholesky (Eigen's SimplicialLDLT, nested-dissection ordering) and refactored
///    only when h, the model (`Model::revision`) or the field's linear terms change; the
///    triangular solves run over the factor rounded to single precision and stored as dense
///    supernodal blocks (x, y and z together; the two halves of the elimination tree on two
///    threads), for x − y (y the inertial prediction, the right-hand
///    side less A y in double: the rounding scales with the step's displacement, not with the
///    coordinates). Starts from
///    the inertial prediction x₀ + h v₀ (warm start: the last step's velocity), runs
///    `projective_iterations` local/global iterations (more, up to a cap, until the iterates
///    settle within `projective_tolerance` when it is set), v₁ = (x₁ − x₀)/h. Unconditionally stable and dissipative; the springs' own
///    damping (along the spring) is not modelled, the hinges' is. Pinned particles move by h v₀.
///    With contact forces installed (`set_contact_forces`), every local step adds them to the
///    right-hand side.
/// Every integrator is deterministic (same input, same bits, whatever the thread count);
/// projective dynamics' triangular solves and implicit Euler's products and triangular solves
/// (`CgPreconditioner::Rest`) run on up to two threads, the rest on one.

#include <crumple/sim/forces.hpp>

#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace crumple::sim {

enum class IntegratorKind { ExplicitEuler, SymplecticEuler, Rk4, ImplicitEuler, Projective };

/// "explicit-euler", "symplectic-euler", "rk4", "implicit-euler", "projective".
std::string_view to_string(IntegratorKind kind);
/// Parses one of the names above; throws `InputError` listing them.
IntegratorKind parse_integrator(std::string_view name);
/// Every kind, in enum order.
std::span<const IntegratorKind> all_integrators();

/// Preconditioner of implicit Euler's conjugate gradient. Either way CG stops at the same
/// relative residual (`cg_tolerance`) on the same system: the steps agree within it.
enum class CgPreconditioner {
  Diagonal,  ///< A's diagonal (Jacobi), Eigen's `ConjugateGradient`
  /// P⁻¹ = I₃ ⊗ K⁻¹ + B⁻¹ over the free particles: K = M (1 + h air) + Σ_springs (h c + h² k) G
  /// + Σ_hinges (h c + h² s) w wᵀ (G a spring's graph Laplacian), A with each spring's stiffness
  /// and damping taken along all three axes, factored once per model, h and air damping (sparse
  /// Cholesky, as projective dynamics' matrix); B A's 3×3 diagonal blocks, the step's (the
  /// springs' stiffness across them is their tension only, far below K's). Several times fewer
  /// iterations than Jacobi, more so on finer cloths; falls back to `Diagonal` for a step that
  /// does not converge within `cg_max_iterations`.
  Rest,
};

struct IntegratorOptions {
  Scalar cg_tolerance = 1e-8;   ///< relative residual |r|/|b| at which CG stops (implicit)
  int cg_max_iterations = 1000;
  CgPreconditioner cg_preconditioner = CgPreconditioner::Rest;  ///< implicit Euler's CG
  int projective_iterations = 10;  ///< local/global iterations per step (projective, >= 1)
  /// Chebyshev acceleration's spectral radius estimate ρ (projective; 0 = none, < 1).
  Scalar projective_rho = 0;
  /// Projective: > 0 (m) keeps iterating after `projective_iterations` until no free particle
  /// moved more than this in the last iteration, up to `projective_max_iterations`; 0 = exactly
  /// `projective_iterations`. An under-converged step gives back as motion much of the elastic
  /// energy that position corrections (contacts, the fail-safe) store; a converged backward
  /// Euler step dissipates it (docs/simulation.md, "Energy under contact").
  Scalar projective_tolerance = 0;
  int projective_max_iterations = 40;  ///< cap with a tolerance (>= projective_iterations)
  /// Threads of the projective solve's triangular sweeps (0 = all hardware threads, at most 2
  /// used; 1 = serial). The result is the same bits on any number.
  int threads = 0;
};

/// The global step's response to forces: displacement = A⁻¹ force over the free particles (#V
/// entries each; 0 at a pinned particle), A the step's constant system matrix.
using ContactSolve = std::function<void(std::span<const Vec3> force, std::span<Vec3> displacement)>;
/// Contact forces inside a projective step: called at every local step with the iterate (#V
/// positions), the diagonal of the step's constant system matrix per particle (0 for a pinned
/// one) and the global step's response (`ContactSolve`, one more triangular solve per call);
/// writes a force per particle (#V, zero where there is none), which the global step adds to
/// its right-hand side. The factored matrix does not change: the forces are the contacts' share
/// of the local step (docs/simulation.md, "Contacts in the projective step").
using ContactForces = std::function<void(std::span<const Vec3> iterate, std::span<const Scalar> diagonal,
                                         const ContactSolve& solve, std::span<Vec3> force)>;

/// A pull held inside an implicit step: a zero-rest-length spring along `direction` (unit)
/// whose target is `offset` (>= 0) beyond the particle's start of step, d · x = d · x₀ + s with
/// s = max(offset, h d · v₀) (a particle already moving farther that way keeps its motion). Its
/// energy ½ k (d · x − d · x₀ − s)², k = stiffness × D / h², D the particle's diagonal (mean of
/// its 3×3 block) of the step's matrix without anchors, is part of the backward Euler system:
/// the springs share the pull with the particle's neighbours within the step instead of taking
/// it back at the next one (docs/simulation.md, "Untangling"). A particle whose neighbours stay
/// ends the step about stiffness / (1 + stiffness) of the way to the target.
struct Anchor {
  Index vertex = -1;
  Vec3 direction = Vec3::Zero();
  Scalar offset = 0;
};

class Integrator {
 public:
  virtual ~Integrator() = default;
  /// Whether `set_contact_forces` acts (projective dynamics only).
  virtual bool takes_contact_forces() const { return false; }
  /// Installs (or, empty, removes) the contact forces of the following steps; only an
  /// integrator that `takes_contact_forces` uses them.
  void set_contact_forces(ContactForces forces) { contact_forces_ = std::move(forces); }
  /// Whether `set_anchors` acts (implicit Euler only).
  virtual bool takes_anchors() const { return false; }
  /// Installs the anchors of the following steps (stiffness > 0, relative to the particle's
  /// diagonal, see `Anchor`); an empty span removes them. Anchors on pinned particles are
  /// ignored. Only an integrator that `takes_anchors` uses them.
  void set_anchors(std::span<const Anchor> anchors, Scalar stiffness) {
    anchors_.assign(anchors.begin(), anchors.end());
    anchor_stiffness_ = stiffness;
  }
  virtual IntegratorKind kind() const = 0;
  /// Advances `state` (x, v, time) by `dt` seconds (> 0).
  virtual void step(const Model& model, const ForceField& field, State& state, Scalar dt) = 0;
  /// CG iterations of the last step (implicit Euler), local/global iterations (projective), 0
  /// for explicit schemes.
  int last_iterations() const { return last_iterations_; }
  /// Sparse factorizations so far (projective dynamics: one per model, step or field change;
  /// implicit Euler with `CgPreconditioner::Rest`: one per model, step or air damping change;
  /// 0 for the other schemes).
  std::int64_t factorizations() const { return factorizations_; }

 protected:
  int last_iterations_ = 0;
  std::int64_t factorizations_ = 0;
  ContactForces contact_forces_;
  std::vector<Anchor> anchors_;
  Scalar anchor_stiffness_ = 0;
};

/// The largest step h (s) at which `kind` keeps the linearized motion of `model` at shape `x`
/// (#V positions) from growing, tension left out: every eigenvalue λ of M x'' + C x' + K x = 0
/// (springs, hinges, their damping, the field's air damping and drag) is a root of
/// λ² + cλ + k = 0 for a pair (c, k) within 0 ≤ k ≤ k_max, c − air ≤ c_max and
/// τ_min k ≤ c − air ≤ τ_max k (τ: each element's damping-to-stiffness ratio; k_max, c_max: the
/// largest eigenvalues of M^-1/2 K M^-1/2 and M^-1/2 C M^-1/2 by power iteration, at most their
/// Gershgorin bounds), and h is the largest step whose amplification stays in the unit disc for
/// every such pair (checked on a grid): |R(hλ)| ≤ 1 for explicit Euler (R = 1 + z) and RK4, the
/// 2×2 step matrix for symplectic Euler. The stiff, overdamped modes of a Kelvin–Voigt material
/// (λ ≈ −τk, real) bound explicit Euler at h ≤ 2/|λ| and RK4 at 2.79/|λ|; an undamped spring
/// makes explicit Euler unstable at every step (0). Implicit Euler and projective dynamics:
/// infinity (unconditionally stable); infinity also without elastic forces.
/// Not covered, so an estimate rather than a guarantee: a shape whose springs line up more than
/// at `x` (k_max grows up to its Gershgorin bound), contacts and obstacles, and the tension of
/// stretched springs, an undamped transverse stiffness k (1 − L/l) on which explicit Euler gains
/// energy by about 1 + (hω)²/2 per step unless the air damping absorbs it.
Scalar stable_time_step(const Model& model, const ForceField& field, std::span<const Vec3> x, IntegratorKind kind);

std::unique_ptr<Integrator> make_integrator(IntegratorKind kind, const IntegratorOptions& options = {});

}  // namespace crumple::sim
