#pragma once
// Measurement primitives of `crumple bench`: record a simulated scene once, then time any
// detector on the same recorded frames, in order (the stochastic detector needs the temporal
// coherence of consecutive frames), with its per-frame recall against a reference run.

#include <crumple/detect/compare.hpp>
#include <crumple/detect/detector.hpp>
#include <crumple/mesh/mesh.hpp>
#include <crumple/sim/scene.hpp>

#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

namespace crumple::bench {

using sim::Recording;
using sim::record_scene;

/// One method timed on a sequence of frames.
struct Timing {
  std::string spec;
  std::vector<double> ms;           ///< per timed frame: median over the repetitions
  std::vector<ContactMatch> match;  ///< per timed frame against the reference (the first method)
  /// Mean over the timed frames of the detector's `distance_evals` counter (stochastic only).
  double distance_evals = 0;
};

/// What to time: frames `[first, last)` of `frames` are fed in order to a fresh detector,
/// each with the previous frame as motion; frames before `timed_from` warm the detector up
/// (fed, not timed). Every repetition starts from a fresh detector, so a seeded method does the
/// same work each time; the median per frame is kept.
struct TimingPlan {
  std::size_t first = 0;
  std::size_t timed_from = 0;
  std::size_t last = 0;
  int repetitions = 3;
};

/// One detector update of a timing run: `frame` with the motion from `previous` (the same frame
/// for the first update of a run: no motion); `timed` or a warm-up.
struct FeedStep {
  std::size_t frame = 0;
  std::size_t previous = 0;
  bool timed = false;
  bool operator==(const FeedStep&) const = default;
};

/// The updates one repetition of `plan` makes, in order.
std::vector<FeedStep> feed_steps(const TimingPlan& plan);

/// The scaling section's plan for a folding lattice: frames 6 and 7 warm the detector up (the
/// stochastic one's kept pairs, the exact ones' tree, table or sort order), then `timed` frames
/// from 8 are timed, each with the motion from the one before. Frames before `first` are never
/// fed.
TimingPlan lattice_scaling_plan(std::size_t timed, int repetitions);
/// The plan for a pair of real frames (0, 1), as in `exact_bench`: an untimed update on frame 0,
/// then frame 1 timed with the motion from frame 0.
TimingPlan frame_pair_plan(int repetitions);

/// Times several methods on the same frames, interleaved by repetition: repetition r of every
/// method (each a fresh detector fed the whole sequence in order, its caches warm as when it
/// runs alone) before repetition r + 1 of any. The median per frame then comes from runs spread
/// over the whole measurement, and a drift of the machine's speed over minutes (shared VMs)
/// lands on every method's runs alike, so their ratios hold. The first method is the
/// reference: every method's contacts (its own included) are matched against its contacts of
/// the same frame. `on_run(repetition, method)` reports progress.
std::vector<Timing> time_methods_against_first(std::shared_ptr<const Topology> topology,
                                               const std::vector<Positions>& frames,
                                               const std::vector<std::string>& specs, const DetectorOptions& options,
                                               const TimingPlan& plan,
                                               const std::function<void(int, std::size_t)>& on_run = {});

/// Machine description for the report: CPU model, hardware threads, compiler.
std::string machine_description();
/// `git describe`-like identity of the source tree (`unknown` when git or the tree is absent).
std::string source_commit();
/// Current UTC date and time, ISO 8601.
std::string utc_now();

}  // namespace crumple::bench
