#pragma once
/// \file
/// The continuous-collision fail-safe of a frame: given the positions x⁰ at the frame's start
/// and the proposed positions x¹ at its end (after integration and the proximity response), it
/// changes x¹ (and the end velocities) so that the linear motion x(t) = x⁰ + t (x¹ − x⁰),
/// t ∈ [0, 1], brings no vertex–face or edge–edge pair into contact. Hence
/// **if x⁰ is intersection-free, so is x¹** (no two triangles sharing no vertex intersect):
/// two such triangles can only start to intersect by touching, and the first touch is a VF or
/// an EE contact, which the continuous query never misses (detect/continuous.hpp).
///
/// Stages, each ending as soon as the query (with minimum separation δ) reports no live impact
/// (see `CcdFailSafe::apply` for "live"); the motion is handled as the frame's displacements
/// uᵢ = x¹ᵢ − x⁰ᵢ:
///  1. CCD impulses (Bridson, Fedkiw, Anderson, SIGGRAPH 2002, §7.2): for each impact, an
///     inelastic impulse in the stencil form of `contact_response.hpp` (weights and normal at
///     the time of impact) removes the pair's approaching relative normal displacement,
///     Gauss–Seidel, for `impulse_rounds` rounds, a query after each; a round that applies no
///     impulse ends the stage, and after a query that returns the last query's pairs again the
///     rounds run on those pairs alone (re-tested per round) until the next query;
///  2. impact zones (Provot 1997; Bridson et al. 2002, §7.4): the vertices of impacting pairs
///     are merged into zones (union–find, zones only grow), and each zone moves rigidly with the
///     mass-weighted mean displacement and the rotation of its angular momentum
///     (θ = I⁻¹ Σ mᵢ rᵢ × (uᵢ − ū), x¹ᵢ = x_c + ū + R(θ) rᵢ), for `zone_rounds` rounds, ending
///     early when a round's zones are the last round's (moving them again changes nothing);
///  3. the fallback that cannot fail: every vertex of a live impact keeps its start position
///     (uᵢ = 0), repeated until no live impact has a moving vertex. The frozen set grows every
///     round, so this ends within #V rounds; a live impact left has all its vertices frozen,
///     so it is a static pair at its start distance, which cannot touch if x⁰ was
///     intersection-free (docs/simulation.md gives the whole argument).
/// Velocities follow the positions: a vertex the fail-safe moved gets the frame's mean velocity
/// v = uᵢ / H (H the frame's duration; adding the change to the integrator's end velocity
/// instead pumps energy into a cloth pressed against walls); a frozen vertex gets v = 0; the others keep
/// theirs.
/// Pinned vertices (m⁻¹ = 0) are not moved by impulses; a zone holding pinned vertices only
/// translates with their mean displacement; the fallback freezes them like any other vertex
/// (the guarantee comes first; the scene's kinematics set them again at the next step).

#include <crumple/core/types.hpp>
#include <crumple/detect/continuous.hpp>
#include <crumple/response/contact_response.hpp>

#include <cstddef>
#include <memory>
#include <span>
#include <vector>

namespace crumple::response {

struct FailSafeOptions {
  /// δ ≥ 0 (scene units): impacts are pairs that come within δ during the frame.
  Scalar min_separation = 0;
  /// Rounds of CCD impulses (>= 0). Impulses change only the approaching normal part of a
  /// pair's motion; a zone moves its vertices by up to their whole proposed displacement and
  /// leaves the springs at its border stretched (many times their rest length in a squeezed
  /// pile), energy the next step gives back as motion (docs/simulation.md, "Energy under
  /// contact"). So impulses run until the query is clean, up to this many rounds, before zones.
  int impulse_rounds = 20;
  int zone_rounds = 8;     ///< rounds of impact zones (>= 0)
  /// The continuous query's broad phase, threads and narrow-phase options.
  ContinuousOptions query{};
  /// After the first query of a frame, query only the pairs holding a vertex whose proposed
  /// end moved since the last query (`ContinuousQuery::update_moved`): the same impacts, bit
  /// for bit, at a cost that follows the corrected region. A later `apply` from the same start
  /// (bit for bit) continues likewise from the last query. Off: every query sweeps the mesh.
  bool restrict_queries = true;
  /// A restricted query (a later one, or the first with a `StartProximity`) runs while it covers
  /// at most this share of the vertices, else the sweep (the same impacts). The restricted
  /// query's cost follows the faces it covers (each queries a tree of every face); on the
  /// sphere's landing a quarter or a half changed the fail-safe's work by under 1 %
  /// (docs/simulation.md, "The CCD fail-safe").
  Scalar restricted_share = 0.125;
  /// The first query with a `StartProximity` also leaves out the pairs whose vertices move
  /// together (`ContinuousQuery::MotionBound`, reach s): a pair with a relative displacement
  /// within s that is not listed near started farther than R and stays beyond δ (1 + σ), and
  /// a listed one is exempt unless its own test clears it (docs/simulation.md, "Pairs that
  /// move together"). The same impacts otherwise; the sweep drops such face pairs and orphans
  /// before testing them, the restricted query whole subtrees of its tree.
  bool motion_bound = true;
};

/// What the caller knows of the frame's start, to spare the first query the sweep of the whole
/// mesh (`CcdFailSafe::apply`): `pairs` holds every VF and EE pair (a vertex and a face it is
/// not a corner of; two edges sharing no vertex) closer than `radius` at the frame's start, with
/// its distance there — a complete proximity detection at that radius, e.g. an exact detector's
/// contacts. A pair missing from it voids the guarantee; extra pairs are harmless.
struct StartProximity {
  Scalar radius = 0;
  const ContactSet* pairs = nullptr;
};

/// What one `apply` did.
struct FailSafeStats {
  /// Continuous queries run (full sweeps or `update_moved` calls). A clean frame is one check:
  /// a query, or an `unchanged` one.
  int queries = 0;
  /// Checks answered without a query (`restrict_queries`): no end had moved since the last
  /// query, so its impacts stand, bit for bit (e.g. after a round that applied no impulse, or
  /// a second `apply` from the same start with the same ends). With `restrict_queries` off,
  /// each of them is a full query instead: `queries + unchanged` is the same either way.
  int unchanged = 0;
  std::size_t impacts = 0;     ///< live impacts of the proposed motion (first check)
  /// Vertices the first query was restricted to (`StartProximity`; when `first_restricted`).
  std::size_t first_flagged = 0;
  bool first_restricted = false;  ///< the first query was so restricted
  int impulse_rounds = 0;      ///< impulse rounds run (including `retested_rounds`)
  /// Impulse rounds run on the last query's pairs alone, each re-tested by the narrow phase
  /// instead of queried (after a query returned the pairs of the one before; file comment).
  int retested_rounds = 0;
  int zone_rounds = 0;         ///< zone rounds run
  std::size_t zone_vertices = 0;  ///< vertices in impact zones
  std::size_t frozen = 0;      ///< vertices kept at their start positions by the fallback
  std::size_t static_left = 0;  ///< live impacts left between frozen vertices (false positives)
};

/// A fail-safe over one topology, kept across frames (the query's structures are refitted).
class CcdFailSafe {
 public:
  /// Throws `InputError` for bad query options or negative round counts.
  CcdFailSafe(std::shared_ptr<const Topology> topology, FailSafeOptions options);

  /// Makes the motion from `start` to `positions` free of VF/EE contact (see the file
  /// comment); `inv_mass`, `start`, `positions`, `velocities` have #V entries, `duration` > 0
  /// is the frame's length H (s). Impacts are *live* unless the pair is within δ already at
  /// the frame's start and never touches during the frame (certified by the narrow phase with
  /// δ = 0): those pairs the proximity response handles, and freezing them would glue them;
  /// nor is a pair reported above δ inside the narrow phase's tolerance band (`kHitTolerance`,
  /// within δ (1 + σ)) that the narrow phase with δ (1 − σ) certifies never comes that close:
  /// it grazes δ, and no impulse (they remove an approach only) moves it out of the band.
  ///
  /// With `proximity` (and `restrict_queries`), the first query of a frame is restricted to the
  /// pairs holding a *flagged* vertex (`ContinuousQuery::query_moved`), with the full query's
  /// impacts. With s = R − δ (1 + σ) − m (R = `radius`, σ the narrow phase's tolerance band, m a
  /// tenth of R − δ (1 + σ) plus a rounding margin), a vertex is flagged when its displacement uᵢ
  /// lies farther than s/2 from a common reference c, and so are the four vertices of a pair of
  /// `proximity` whose start distance less the largest |uᵢ − uⱼ| across its two sides is below
  /// δ (1 + σ) + m. Any two points of a pair move apart or together by at most the largest
  /// |uᵢ − uⱼ| across its sides (convex combinations), so a pair with no flagged vertex stays
  /// beyond δ (1 + σ) + m: if it was R or more apart, since that is at most s; if closer, it is
  /// in `proximity` and passed its own test. The whole mesh is swept instead when more than
  /// `FailSafeOptions::restricted_share` of the vertices are flagged (docs/simulation.md, "The CCD
  /// fail-safe"). With `FailSafeOptions::motion_bound` the same argument also runs pair by pair:
  /// every pair of `proximity` is tested (its vertices *exempt* when the test fails), and the
  /// first query, restricted or the sweep, leaves out the pairs with no exempt vertex whose
  /// largest |uᵢ − uⱼ| across the sides is at most s (`ContinuousQuery::MotionBound`).
  FailSafeStats apply(PositionsView start, std::span<const Scalar> inv_mass, Scalar duration,
                      std::span<Vec3> positions, std::span<Vec3> velocities,
                      const StartProximity* proximity = nullptr);

  /// Vertices of an existing intersection being untangled (#V flags; empty = none): an impact
  /// with a flagged vertex on each of its sides is not live, so the fail-safe lets the tangle
  /// move through itself (`response/untangle.hpp`). The guarantee then covers the other pairs.
  void set_tangle(std::span<const char> tangle) { tangle_.assign(tangle.begin(), tangle.end()); }

  const FailSafeOptions& options() const { return options_; }
  /// The continuous query (its statistics of the last query).
  const ContinuousQuery& query() const { return query_; }

 private:
  /// Runs the query from `start` to `positions` and fills `live_` with the live impacts (the
  /// first query of a frame restricted by `proximity` when given; see `apply`).
  std::size_t detect(PositionsView start, std::span<const Vec3> positions, FailSafeStats& stats,
                     const StartProximity* proximity = nullptr);
  /// Whether a query covering `count` of `n` vertices runs restricted (`restricted_share`).
  bool restricted(std::size_t count, std::size_t n) const {
    return static_cast<Scalar>(count) <= options_.restricted_share * static_cast<Scalar>(n);
  }
  static constexpr std::size_t kUnrestricted = static_cast<std::size_t>(-1);
  /// Flags in `moved_` the vertices the first query must cover (see `apply`) and, with
  /// `motion_bound`, in `exempt_` those of the listed pairs their own test does not clear
  /// (`motion_valid_` then set, for a restricted query or a sweep); returns the count of
  /// `moved_`, or `kUnrestricted` when `proximity` allows no restricted query (no bound, or
  /// more than `restricted_share` of the vertices flagged).
  std::size_t flag_first_query(PositionsView start, std::span<const Vec3> positions,
                               const StartProximity& proximity);

  std::shared_ptr<const Topology> topology_;
  FailSafeOptions options_;
  ContinuousQuery query_;
  ImpactSet impacts_;
  std::vector<Stencil> live_;
  std::vector<char> tangle_;
  std::vector<Vec3> queried_;  ///< the end positions of the last query (`restrict_queries`)
  /// `impacts_` are the query of the motion from `start_` to `queried_` (a query answered).
  bool queried_valid_ = false;
  std::vector<Vec3> start_;  ///< the start of the last `apply` (`restrict_queries`)
  bool same_start_ = false;  ///< this `apply`'s start is the last one's, bit for bit
  std::vector<char> moved_;    ///< per vertex, whether its end moved since the last query
  std::vector<char> exempt_;   ///< `flag_first_query`'s exempt vertices (`motion_bound`)
  Scalar motion_reach_ = 0;    ///< `flag_first_query`'s s (`motion_bound`)
  bool motion_valid_ = false;  ///< `exempt_` and `motion_reach_` hold for this frame's first query
  std::vector<Scalar> scratch_;                ///< `flag_first_query`'s
};

}  // namespace crumple::response
