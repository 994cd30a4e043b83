#pragma once
/// \file
/// The exact detector (`kdop`, `hash`, `sap`): a broad phase it is given (broad_phase/), then
/// the same pipeline for every broad phase, in stages (detect/exact/, docs/exact-detectors.md):
///
///  1. feature ownership (exact/ownership.hpp), once per topology: every vertex and every edge
///     is owned by one of its faces ("representative triangles", Curtis, Tamstorf & Manocha
///     2008), chosen so that many faces own no vertex and many no edge;
///  2. broad phase, every frame: the pairs of faces sharing no vertex that lie within the
///     padded thickness (each face inflated by half of it), each once (broad_phase.hpp); in a
///     proximity query it may leave out pairs that own no sub-pair (`FrameInput::owns`);
///  3. narrow phase per pair kind (exact/narrow_candidates.cpp): in each candidate pair, the
///     sub-pairs its faces own, VF (v, g) only in {owner(v), g}, EE (e1, e2) only in
///     {owner(e1), owner(e2)}, so each is tested in exactly one place; TT on every candidate;
///  4. orphans (exact/orphans.hpp): the VF and EE sub-pairs of faces that share a vertex, which
///     no broad phase emits, listed once per topology, tested in blocks that sleep while they
///     provably hold no contact; around vertices of high valence (stars), found per frame from
///     a box tree instead (a list is quadratic there); isolated vertices (used by no face)
///     against the faces whose boxes come within reach;
///  5. gather (exact/gather_contacts.cpp): the contacts of every chunk, in canonical order.
///
/// Exactness: two features closer than h lie in faces closer than h, so in a candidate pair
/// or an adjacent pair, and the pair of their owners is that pair. Every rejection before the
/// exact kernels (boxes, separating planes and lines) keeps anything within the padded
/// thickness, and the kernels are those `naive` calls, with the same argument order, so the
/// contacts and their distances are the same bits as the oracle's.
///
/// Rounding: every box and rejection test uses the padded thickness `pad = h (1 + 1e-6) + 1e-9
/// M` (M = largest coordinate magnitude of the frame) rather than h, so a pair the kernels
/// place just under h is never rejected by a test evaluated in different arithmetic. When only
/// TT is asked, the thickness plays no part and `pad` is the rounding margin alone.

#include <crumple/core/error.hpp>
#include <crumple/core/frame_deadline.hpp>
#include <crumple/detect/broad_phase/broad_phase.hpp>
#include <crumple/detect/detector.hpp>

#include <cstddef>
#include <memory>

namespace crumple {

/// Thrown by an exact detector when the contacts of a frame exceed `max_contacts` and
/// `overflow=error` (the default).
class ContactOverflowError : public Error {
 public:
  using Error::Error;
};

namespace exact {
class Cutoff;  // exact/narrow_frame.hpp
}

/// Keys common to the exact detectors (`max_contacts`, `overflow`), and `kdop`'s cut-off
/// (`budget`, `pairs`).
///
/// Cut-off frames (the naive way to keep a time budget with an exact method; docs/hybrid.md):
/// the broad phase streams its candidates to the narrow phase as it finds them (`kdop`: after
/// each traversal task, in the tree's order), each block of candidates is claimed from the budget
/// before it is tested, and once the budget is spent the traversal and the narrow phase stop
/// and the orphan stages not yet begun are skipped (each stage runs whole or not at all). The
/// frame returns the contacts found so far, in canonical order: a subset of the full set, with
/// the same bits. With `pairs` alone the cut point is a count of candidates, so the contacts
/// depend only on the frames (one thread; with more, on the threads' interleaving too). Without
/// `track`, a larger `pairs` finds a superset on every frame.
struct ExactParams {
  std::size_t max_contacts = 0;  ///< cap on the contacts of one frame; 0 = no cap
  bool overflow_error = true;    ///< over the cap: throw (true) or keep the first contacts
  double budget_ms = 0;          ///< time budget per frame from the start of `update`; 0 = none
  std::size_t pairs = 0;         ///< at most this many candidates narrow-tested per frame; 0 = all
  BudgetClock clock = BudgetClock::wall;  ///< what `budget_ms` counts (cpu: one thread only)
  /// Cut-off frames first re-test the last frame's contacts (most persist from frame to frame),
  /// and the traversal begins where the last one stopped (`kdop`), so that frames cut short
  /// cover the mesh in turn; the orphan stages, when the budget has skipped them for 4 frames,
  /// run before the traversal. The result is still a subset with the same bits, without
  /// duplicates (a contact found twice is reported once).
  bool track = false;
  bool cut_off() const { return budget_ms > 0 || pairs > 0; }
  static ExactParams from_spec(const MethodSpec& spec);
  bool operator==(const ExactParams&) const = default;
};

/// The exact detector over the broad phase it owns (`KdopTree`, `HashGrid`, `SweepPrune`;
/// make_detector.cpp picks one from the spec). Its method is the broad phase's.
class ExactDetector final : public Detector {
 public:
  ExactDetector(DetectorOptions options, ExactParams params, std::unique_ptr<BroadPhase> broad_phase);
  ~ExactDetector() override;
  Method method() const override { return broad_phase_->method(); }
  const BroadPhase& broad_phase() const { return *broad_phase_; }
  /// The broad phase's hierarchy (kdop), its boxes in the coordinates given to `update`.
  const BoundingHierarchy* hierarchy() const override;
  /// True when the last frame had more contacts than `max_contacts` (also in stats:
  /// `overflow` = 1, `contacts_dropped`).
  bool overflowed() const { return overflowed_; }

 protected:
  /// The contacts are gathered in canonical order (`exact::gather_contacts`).
  bool sorted_output() const override { return true; }
  /// `clock=cpu` counts one thread: a time budget then needs `threads` = 1.
  void check_budget(double ms) const override;
  double spec_budget_ms() const override { return params_.budget_ms; }
  BudgetClock budget_clock() const override { return params_.clock; }

 private:
  struct State;  // exact_detector.cpp
  class Unscaled;  // exact_detector.cpp: the hierarchy with its boxes scaled back

  void on_topology() final;
  /// Rebuilds the broad phase and wakes the orphan blocks: both keep coordinates.
  void on_rescale() final;
  void detect(PositionsView previous, PositionsView positions, ContactSet& out) final;
  /// The frame's largest coordinate magnitude (of `previous` too), and the float positions.
  Scalar prepare_frame(PositionsView previous, PositionsView x);
  /// Stages 3 to 5 over the broad phase's candidates; `magnitude` as `prepare_frame` gives it.
  /// With `cut` or `stream`, the broad phase's candidates are streamed (`self_pairs` is called
  /// here) and tested as they come; with `cut`, cut off as `ExactParams` says.
  void narrow_phase(PositionsView x, Scalar pad, Scalar magnitude, ContactSet& out, exact::Cutoff* cut,
                    bool stream = false);
  /// Applies `max_contacts` (throws or truncates) and sets the contact stats.
  void cap_contacts(ContactSet& out);
  /// With `track`, keeps the frame's contacts to test again first next frame.
  void keep_seeds(const ContactSet& out);

  ExactParams params_;
  std::unique_ptr<BroadPhase> broad_phase_;
  std::unique_ptr<State> state_;
  std::unique_ptr<Unscaled> unscaled_;
  bool overflowed_ = false;
};

}  // namespace crumple
