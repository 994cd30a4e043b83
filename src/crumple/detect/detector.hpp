#pragma once
/// \file
/// The one detector interface (STYLE.md §2, §3). Lifecycle: `set_topology` once, then
/// `update(positions)` — or `update(previous, positions)` for methods that use motion — every
/// frame. One virtual call per frame fills a `ContactSet`; state that persists across frames
/// (trees, active pair lists, grids) lives in the detector object.
///
/// Contact definition (the oracle's), with thickness h:
///  - VF: vertex v and face f with v not a corner of f and dist(v, f) < h;
///  - EE: edges sharing no vertex with dist < h;
///  - TT: faces sharing no vertex that intersect (closed triangles; touching counts).

#include <crumple/core/frame_deadline.hpp>
#include <crumple/core/types.hpp>
#include <crumple/core/vertex_view.hpp>
#include <crumple/detect/contact.hpp>
#include <crumple/detect/hierarchy.hpp>
#include <crumple/detect/method.hpp>
#include <crumple/mesh/mesh.hpp>

#include <memory>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace crumple {

/// Options common to every detector.
struct DetectorOptions {
  Scalar thickness = 0;  ///< h, in scene units; contact when distance < h. Must be >= 0.
  ContactKinds kinds{};  ///< which kinds to report (default VF + EE)
  int threads = 0;       ///< worker threads: 0 = all hardware threads, 1 = serial
};

/// Named counters of the last update, in a stable order (for `--json` and benchmarks).
class DetectorStats {
 public:
  void clear() { items_.clear(); }
  /// Sets a counter, appending it if new.
  void set(std::string_view key, double value);
  void add(std::string_view key, double value);
  double get(std::string_view key) const;  ///< 0 when absent
  const std::vector<std::pair<std::string, double>>& items() const { return items_; }

 private:
  std::vector<std::pair<std::string, double>> items_;
};

/// Base of every detection method.
class Detector {
 public:
  explicit Detector(DetectorOptions options);
  virtual ~Detector() = default;
  Detector(const Detector&) = delete;
  Detector& operator=(const Detector&) = delete;

  virtual Method method() const = 0;
  Capabilities capabilities() const { return method_info(method()).capabilities; }
  const DetectorOptions& options() const { return options_; }

  /// Sets the mesh connectivity (once, or again to start over: resets all frame state).
  void set_topology(std::shared_ptr<const Topology> topology);
  const Topology& topology() const;

  /// Detects the contacts at `positions` (#V entries). `out`'s contents are replaced by them,
  /// sorted canonically (see `ContactSet::sort`); if it throws, `out` is left empty.
  /// Coordinates of any magnitude: the detection runs on them scaled by a power of two (exact)
  /// when their largest finite magnitude M is outside [2^-64, 2^64), so the contacts at scale
  /// 2^j x are those at x, their distances times 2^j. Throws `InputError` when the finite
  /// coordinates span more than the double range (some non-zero one below about 1e-308 M).
  /// NaN and infinite coordinates are accepted: no contact involves them.
  void update(PositionsView positions, ContactSet& out);
  /// Same, with the previous frame's positions for methods that use motion (others ignore them,
  /// and are given none).
  void update(PositionsView previous, PositionsView positions, ContactSet& out);
  /// Same, from a host application's buffers (`float` or `double`, packed or strided, see
  /// `VertexView`): a native view is read in place, any other is converted once into the
  /// detector's own buffer (reused across frames), `previous` only for methods that use motion.
  /// The contacts are those of `update` on the converted `double` positions, bit for bit.
  void update(const VertexView& positions, ContactSet& out);
  void update(const VertexView& previous, const VertexView& positions, ContactSet& out);

  /// Sets the time budget of the frames that follow, in ms (0 = none), in place of the `budget`
  /// key of the methods that keep one (`kdop`, `stochastic`, `hybrid`; counted on the clock of
  /// their `clock` key): a caller may give each frame its own budget. The method's parameters,
  /// and its saved state, keep the spec's value. Throws `InputError` for a method without a
  /// `budget` key, a budget outside [0, 1e6], or one this detector cannot count (`kdop` with
  /// `clock=cpu` needs one thread).
  void set_budget(double ms);

  /// Counters of the last update (pairs tested, candidates, ...), method-specific.
  const DetectorStats& stats() const { return stats_; }

  /// The bounding-volume hierarchy the method keeps (levels, node boxes, leaves; `kdop`), or
  /// null for methods without one. Valid until the detector's next `set_topology`.
  virtual const BoundingHierarchy* hierarchy() const { return nullptr; }

  /// The state carried across frames that changes later results, as one line of text — the
  /// state *before* the last update, so that replaying that update on the same positions gives
  /// the same contacts and ends in the current state (what a resumed simulation needs). Empty
  /// for methods whose results do not depend on earlier frames (every exact method).
  virtual std::string save_state() const { return {}; }
  /// Restores a `save_state` text (the topology must be set). An empty text is always
  /// accepted; text that does not fit this method, its parameters or the topology throws
  /// `InputError`.
  virtual void load_state(std::string_view text);

 protected:
  /// Called after a new topology is set; detectors build their per-mesh structures here.
  virtual void on_topology() {}
  /// Called before a frame whose positions are scaled by another power of two than the last
  /// frame's (`scale_exponent`): state kept in coordinates (boxes, reference positions) must
  /// be dropped here. Index state (kept pairs) stays valid.
  virtual void on_rescale() {}
  /// Replaces the contents of `out` by this frame's contacts. `out` holds whatever the caller
  /// passed (typically the set of an earlier frame): its storage, and its size, may be reused
  /// — rewriting records in place avoids constructing tens of MB of them every frame.
  /// `previous` is empty when no motion is given.
  virtual void detect(PositionsView previous, PositionsView positions, ContactSet& out) = 0;
  /// Whether `detect` itself leaves `out` in canonical order. `update` sorts the output of the
  /// detectors that do not; for those that do, it skips even the check (a pass over every
  /// contact), and the tests check the order of their output instead.
  virtual bool sorted_output() const { return false; }

  /// This frame's time budget in ms: the last `set_budget`, or `spec_ms` (the method's `budget`
  /// key) when it was never called.
  double frame_budget(double spec_ms) const { return budget_set_ ? budget_ms_ : spec_ms; }
  /// The method's `budget` and `clock` keys (0 = none), for `frame_deadline`.
  virtual double spec_budget_ms() const { return 0; }
  virtual BudgetClock budget_clock() const { return BudgetClock::wall; }
  /// This frame's deadline, `frame_budget(spec_budget_ms())` on `budget_clock()`, started at
  /// the entry of `update`: the budget covers the whole call (the pass over the positions for
  /// their magnitude, a conversion of a `VertexView`, the scaling included). None (never
  /// passed) without a budget.
  const FrameDeadline& frame_deadline() const { return deadline_; }
  /// Called by `set_budget` with a budget in [0, 1e6]; throws `InputError` when this detector
  /// cannot keep it.
  virtual void check_budget(double /*ms*/) const {}

  /// The thickness in the coordinates `detect` is given: 2^scale_exponent() h (h from
  /// `options()`), capped where every pair would be a contact (detect/scale_detail.hpp).
  Scalar thickness() const { return thickness_; }
  /// k such that `detect` is given the positions times 2^k (0 for the usual magnitudes); its
  /// contacts' distances are multiplied by 2^-k after it returns.
  int scale_exponent() const { return exponent_; }

  DetectorStats stats_;

 private:
  DetectorOptions options_;
  std::shared_ptr<const Topology> topology_;
  Positions converted_, converted_previous_;  // non-native `VertexView`s as doubles
  Scalar thickness_ = 0;
  int exponent_ = 0;
  bool framed_ = false;                 // a frame ran since the topology was set
  bool budget_set_ = false;             // set_budget was called: budget_ms_ replaces the spec's
  double budget_ms_ = 0;
  Positions scaled_, scaled_previous_;  // the positions times 2^exponent_, when it is not 0
  FrameDeadline deadline_;

  /// Starts this frame's deadline (`frame_deadline`).
  void start_deadline();
  /// `update` once the deadline is started.
  void run_update(PositionsView previous, PositionsView positions, ContactSet& out);
};

/// Creates the detector for a method spec (the one factory, make_detector.cpp). Throws
/// `InputError` on bad parameters. The detector has no topology yet.
std::unique_ptr<Detector> make_detector(const MethodSpec& spec, const DetectorOptions& options);

}  // namespace crumple
