#pragma once
/// \file
/// The stochastic detector with temporal coherence (M. Nesme 2003, §2.8 and §3.2, Algorithms 2
/// and 3; after G. Debunne and L. Raghupathi et al.). Docs: docs/stochastic.md.
///
/// Collisions are local minima of the distance over the set of primitive pairs, and those minima
/// move little between frames. Per pair type (edge–edge EE, vertex–face VF, edge–face EF, and
/// vertex–vertex VV for the `vertex` variant) the detector keeps, across frames, the list of
/// *near* pairs (local minima closer than the near distance) and the list of *colliding* pairs
/// of the last frame. Every `update()`:
///   1. converges each kept near pair to a local minimum of distance (walking to neighbour pairs:
///      element 1 replaced by a topological neighbour, then element 2, ...); deletes it when it
///      ends farther than the near distance or merges into a pair already reached this frame
///      (duplicate); records it when it collides; then takes last frame's unfinished walks
///      further. A walk stops after `steps` moves and goes on next frame;
///   2. draws random pairs (at most `draw` per frame) while fewer than `active` pairs are kept
///      or walking, converging and filtering them the same way;
///   3. propagates from every colliding pair to neighbouring pairs.
/// The cost per frame is bounded by the parameters (`active`, `draw`, `steps`) and by the size of
/// the colliding regions (propagation), not by the mesh size.
///
/// Only the distance function and the neighbour lists are specialised per pair type
/// (stochastic_engine.hpp, generic over "pair traits").
///
/// Output: the same `ContactSet` as every detector, each contact from the shared narrow phase
/// (narrow_phase.hpp, so distances are bit-identical with `naive`), no duplicates, no adjacent
/// pairs, and never a false contact. It may miss contacts (recall < 1): see `compare.hpp`.
/// Deterministic for a given seed, parameters and input sequence (without a time budget,
/// `StochasticParams::budget_ms`); single-threaded
/// (`DetectorOptions::threads` is ignored).

#include <crumple/core/frame_deadline.hpp>
#include <crumple/detect/detector.hpp>

#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <string_view>

namespace crumple {

/// How pairs converge and how collisions propagate (thesis §3.2.2.5).
enum class StochasticVariant {
  /// Move to the *first* closer neighbour pair; pairs reached this frame are remembered in a
  /// hash set. Propagation tests neighbour pairs directly (flood fill, never re-testing a pair).
  Simple,
  /// Same convergence; propagation launches a convergence from each neighbour pair of a
  /// colliding pair (faster, misses an element colliding with two others).
  PropagateByConvergence,
  /// Move to the *closest* neighbour pair, testing all neighbours; every neighbour pair found in
  /// collision on the way is recorded; distances computed this frame are cached. Propagation by
  /// convergence.
  Direct,
  /// Converge on vertex pairs with the L1 (Manhattan) distance, then run the precise VF/EE
  /// tests (and TT when asked) between the faces around the two vertices, with a k-DOP pre-test
  /// per face pair. Propagation floods neighbouring vertex pairs whose zone holds contacts.
  Vertex,
};

/// Which neighbour pairs of a colliding pair (a, b) propagation visits (thesis §3.2.2.4).
enum class Propagation {
  None,
  Linear,  ///< (n(a), b) and (a, n(b)): O(degree), misses frequent cases (thesis fig. 3.5)
  Full,    ///< linear ones plus n(a) × n(b): O(degree^2) locally, visited pairs never re-tested
};

std::string_view to_string(StochasticVariant variant);
std::string_view to_string(Propagation propagation);

/// Parameters of the stochastic detector (all per pair type). Spec keys in brackets.
struct StochasticParams {
  StochasticVariant variant = StochasticVariant::Direct;  ///< [variant]
  Propagation propagation = Propagation::Linear;          ///< [propagation]
  /// Maximum number of near pairs kept per pair type; random draws top the list up to it.
  /// [active]
  int active = 100;
  /// Maximum number of random pairs drawn per frame and pair type (draws stop earlier once
  /// `active` pairs are kept). [draw]; 0 in a spec means "= active".
  int draw = 100;
  /// Near distance as a multiple of the thickness h: a converged pair farther than near·h is
  /// deleted. Must be >= 1. [near]
  Scalar near = 2;
  /// Maximum convergence steps (moves) per pair and frame; a walk that has not reached a local
  /// minimum after them stops where it is and goes on next frame (it counts among the `active`
  /// pairs meanwhile). [steps]
  int steps = 16;
  /// Also run the edge–face pair type (its VF/EE sub-contacts, and TT when asked), in every
  /// variant but `vertex`. Forced on when TT contacts are requested. [ef]
  bool ef = false;
  std::uint64_t seed = 1;  ///< [seed]
  /// Time budget per frame in milliseconds, 0 = none. [budget] When it is spent, the kept pairs
  /// not yet converged are carried over to the next frame as they are, and random draws and
  /// propagation stop (each pair type keeps its pairs before any type draws). A walk or a
  /// propagation step under way finishes, so a frame may overrun by one walk. With a budget the
  /// results depend on the machine's speed: the detector is deterministic only without one.
  double budget_ms = 0;
  BudgetClock clock = BudgetClock::wall;  ///< what budget_ms counts [clock]

  /// Reads a `stochastic:...` spec. `setting=1` (thesis setting 1: active=10, with the variant's
  /// propagation) and `setting=2` (active=100, propagation=none) set defaults that explicit keys
  /// override. Throws `InputError` on bad values.
  static StochasticParams from_spec(const MethodSpec& spec);
  bool operator==(const StochasticParams&) const = default;
  /// Canonical `stochastic:...` text with every key.
  std::string to_string() const;
};

/// The propagation a variant uses when the spec says `propagation=auto`: full for `simple`,
/// linear otherwise.
Propagation default_propagation(StochasticVariant variant);

/// Primitive pair types of the generic engine.
enum class PairType { VV, EE, VF, EF };
std::string_view to_string(PairType type);

/// A pair of primitive ids (a of the first type, b of the second; a < b for VV and EE).
struct PrimitivePair {
  Index a = -1;
  Index b = -1;
  friend bool operator==(const PrimitivePair&, const PrimitivePair&) = default;
};

/// The stochastic detector. Statistics of the last update (`stats()`), totals over pair types
/// then per type with a `vv_`/`ee_`/`vf_`/`ef_` prefix: `drawn` (random pairs drawn), `kept`
/// (near pairs kept for the next frame), `walking` (walks carried to the next frame unfinished,
/// after `steps` moves this frame), `deleted` (converged too far, or duplicate),
/// `duplicates` (of which merged into another pair), `converge_steps` (moves),
/// `distance_evals` (distance kernel calls), `cache_hits`, `propagation_visits` (neighbour
/// pairs visited by propagation), `colliding` (colliding pairs recorded); for the vertex
/// variant also `zone_tests`, `face_pairs`, `kdop_rejects`; with a time budget, `carried`
/// (kept pairs carried over unconverged).
class StochasticDetector final : public Detector {
 public:
  StochasticDetector(DetectorOptions options, StochasticParams params);
  ~StochasticDetector() override;

  Method method() const override { return Method::Stochastic; }
  const StochasticParams& params() const { return params_; }
  /// Near distance in scene units (near × thickness).
  Scalar near_distance() const { return params_.near * options().thickness; }

  /// Pair types the current options and variant run.
  bool runs(PairType type) const;
  /// Near pairs kept after the last update, in a deterministic order.
  std::span<const PrimitivePair> near_pairs(PairType type) const;
  /// Where the unfinished walks stand after the last update (they go on next frame).
  std::span<const PrimitivePair> walking_pairs(PairType type) const;
  /// Colliding pairs of the last update (kept as state, Algorithm 3), in the order recorded.
  std::span<const PrimitivePair> colliding_pairs(PairType type) const;

  /// `stochastic-state-2 <params> rng <generator state> vv N a b ... M a b ... ee N ... M ... vf
  /// ... ef ...`: the generator, and per pair type the N kept near pairs and the M unfinished
  /// walks, as they were before the last update (see `Detector::save_state`).
  std::string save_state() const override;
  /// Checks that the saved parameters equal this detector's and every pair fits the topology.
  void load_state(std::string_view text) override;

 protected:
  void on_topology() override;
  void detect(PositionsView previous, PositionsView positions, ContactSet& out) override;
  double spec_budget_ms() const override { return params_.budget_ms; }
  BudgetClock budget_clock() const override { return params_.clock; }

 private:
  struct Impl;
  StochasticParams params_;
  std::unique_ptr<Impl> impl_;
};

}  // namespace crumple
