#pragma once
/// \file
/// The hybrid detector (docs/hybrid.md): the thesis' future work (Nesme 2003, §4.2; SPEC.md
/// §9.1–2) — the stochastic search with temporal coherence run *inside* a coarse hierarchy of
/// bounding volumes, under a per-frame time budget, with parameters that adapt per zone.
///
///  - Leaves: connected patches of at most `leaf` faces grown over the face adjacency from the
///    topology alone (so the same mesh always gives the same leaves). Each frame every leaf's box
///    is refitted around its vertices (and their previous positions when given) and inflated by
///    half its near distance plus its largest vertex displacement over the last step (motion
///    inflation: a zone exists the frame before its contact).
///  - Zones: the pairs of leaves whose boxes overlap, a leaf with itself included, found by a
///    binary tree over the leaf boxes rebuilt every frame. Every pair of primitives closer than
///    the near distance lies in a zone (owner leaves, below).
///  - Each frame the zones are examined in order: first those *due* (never examined, or not
///    examined for `every` frames), oldest first; then by priority (contacts found there last
///    time, closeness of the two boxes, approach speed). Examining a zone runs, for each pair
///    type, the thesis' Algorithm 3 restricted to it: its kept pairs converge (direct
///    convergence, stochastic_engine.hpp), random pairs of its own elements are drawn and
///    converged (`search=stochastic`; or, `search=exact`, every pair of its elements is tested
///    behind a box pre-test), and collisions propagate. The time budget (`budget`), or a cap on
///    the zones per frame (`zones`), stops the examinations; the zones left wait, with their kept
///    pairs, and come first next frame since they are older.
///  - Adaptive parameters per zone (§4.2.1, from the thesis' rule of thumb): draws from the
///    zone's particles (each leaf's shared among its zones) and its share in collision last time
///    (10% of its particles below 30%, one per particle above 50%), optionally propagation
///    dropped above 50% (`propagation=auto`), and the near distance from the leaves' measured
///    motion per frame.
///
/// Every primitive has an owner leaf: a face its leaf; a vertex the leaf of its first incident
/// face, an edge that of its first incident face. A pair's zone is that of its owners.
///
/// Output: the same `ContactSet` as every detector, each contact from the shared narrow phase
/// (bit-identical with `naive`); never a false contact; may miss contacts (recall < 1) unless
/// `search=exact` examines every zone. Deterministic for a seed, parameters and input sequence
/// when there is no time budget. Single-threaded. Vertices with no face are never tested.

#include <crumple/core/frame_deadline.hpp>
#include <crumple/detect/detector.hpp>
#include <crumple/detect/stochastic.hpp>

#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <string_view>

namespace crumple {

/// How a zone is searched.
enum class ZoneSearch {
  Stochastic,  ///< random pairs of the zone's elements, converged (the thesis' search)
  Exact,       ///< every pair of the zone's owned elements, behind a box pre-test
};

std::string_view to_string(ZoneSearch search);

/// Parameters of the hybrid detector. Spec keys in brackets.
struct HybridParams {
  int leaf = 64;                                  ///< faces per leaf, in [4, 4096] [leaf]
  int every = 1;                                  ///< a zone is due after this many frames [every]
  double budget_ms = 0;                           ///< time budget per frame, 0 = none [budget]
  BudgetClock clock = BudgetClock::wall;          ///< what budget_ms counts [clock]
  int zones = 0;                                  ///< zones examined per frame at most, 0 = all [zones]
  ZoneSearch search = ZoneSearch::Stochastic;     ///< [search]
  int draw = 0;                                   ///< draws per zone and pair type, 0 = adaptive [draw]
  /// `auto`: the thesis' rule per zone (linear propagation, none above 50% in collision);
  /// else `propagation` in every zone. [propagation = auto | none | linear | full] The default
  /// is `linear`: dropping propagation in busy zones saved little time and lost recall
  /// (docs/hybrid.md).
  bool auto_propagation = false;
  Propagation propagation = Propagation::Linear;
  /// Near distance as a multiple of h; 0 = adaptive per leaf: max(2, 1 + 2 m / h), at most 8,
  /// m = the leaf's largest vertex displacement over the last step. [near]
  Scalar near = 0;
  int steps = 8;           ///< convergence moves per walk and frame [steps]
  std::uint64_t seed = 1;  ///< [seed]

  /// Reads a `hybrid:...` spec; throws `InputError` on bad values.
  static HybridParams from_spec(const MethodSpec& spec);
  bool operator==(const HybridParams&) const = default;
  /// Canonical `hybrid:...` text with every key.
  std::string to_string() const;
};

/// A zone after the last update.
struct ZoneInfo {
  Index leaf_a = -1;  ///< leaf_a <= leaf_b
  Index leaf_b = -1;
  /// Frames since the zone was last examined (0: examined in the last update).
  int age = 0;
  bool examined = false;  ///< examined in the last update
  /// Contacts of the zone found when it was last examined.
  int contacts = 0;
};

/// The hybrid detector. Statistics of the last update (`stats()`), the risk report first:
/// `leaves`, `zones` (overlapping leaf pairs), `zones_examined`, `zones_due` (due at the start of
/// the frame), `zones_due_left` (due and not examined: the coverage promise was not kept),
/// `oldest_zone_age` (frames since the least recently examined zone was examined; < `every`
/// when every due zone was examined), `est_missed` (estimated contacts missed: over the zones
/// not examined, the contacts found at their last examination minus those found this frame),
/// then the work: `drawn`, `kept`, `carried` (kept pairs of unexamined zones carried over),
/// `converge_steps`, `distance_evals`, `propagation_visits`, `colliding`, `exact_pairs` (pairs
/// tested by exact zone searches), and `refit_ms`, `zones_ms`, `search_ms` (timings).
class HybridDetector final : public Detector {
 public:
  HybridDetector(DetectorOptions options, HybridParams params);
  ~HybridDetector() override;

  Method method() const override { return Method::Hybrid; }
  const HybridParams& params() const { return params_; }

  /// Number of leaves (after `set_topology`).
  Index num_leaves() const;
  /// Faces of leaf i.
  std::span<const Index> leaf_faces(Index leaf) const;
  /// Zones of the last update, sorted by (leaf_a, leaf_b).
  std::span<const ZoneInfo> zones() const;

  /// `hybrid-state-1 <params> rng <generator> zones N (a b age never contacts) ... kept M
  /// (type a b) ...`: the state before the last update (see `Detector::save_state`).
  std::string save_state() const override;
  /// Checks that the saved parameters equal this detector's and every entry fits the topology.
  void load_state(std::string_view text) override;

 protected:
  void on_topology() override;
  void detect(PositionsView previous, PositionsView positions, ContactSet& out) override;
  double spec_budget_ms() const override { return params_.budget_ms; }
  BudgetClock budget_clock() const override { return params_.clock; }
  /// `detect` sorts its contacts itself, inside the budget.
  bool sorted_output() const override { return true; }

 private:
  struct Impl;
  HybridParams params_;
  std::unique_ptr<Impl> impl_;
};

}  // namespace crumple
