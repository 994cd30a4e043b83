#pragma once
/// \file
/// Recall/precision harness: runs a detector and a reference (normally `naive`) on the same
/// frame sequence and reports, per frame, the contacts found, missed and false, the recall and
/// the time of each. Generic over any two detectors and any frame source; used by the tests,
/// `crumple compare` and the benchmarks.
///
/// Contacts are matched by identity — VF by (vertex, face), EE by the two edges' vertex ids,
/// TT by the two faces — not by distance (both sides use the shared narrow phase, so a
/// matched contact has the same distance bit for bit).

#include <crumple/detect/detector.hpp>
#include <crumple/mesh/mesh.hpp>

#include <cstddef>
#include <cstdint>
#include <functional>
#include <span>
#include <string>
#include <vector>

namespace crumple {

/// Frames of one deforming mesh (same topology for every frame).
class FrameSource {
 public:
  virtual ~FrameSource() = default;
  virtual std::size_t size() const = 0;
  /// Topology and first-frame positions.
  virtual const TriMesh& mesh() const = 0;
  /// Positions of frame i (#V entries).
  virtual Positions positions(std::size_t i) const = 0;
  /// A label for frame i (a file name, or `name#i`).
  virtual std::string name(std::size_t i) const = 0;
};

/// Frames given as position arrays of one mesh.
class VectorFrames final : public FrameSource {
 public:
  VectorFrames(TriMesh mesh, std::vector<Positions> frames, std::string label = "frames");
  std::size_t size() const override { return frames_.size(); }
  const TriMesh& mesh() const override { return mesh_; }
  Positions positions(std::size_t i) const override { return frames_.at(i); }
  std::string name(std::size_t i) const override { return label_ + "#" + std::to_string(i); }

 private:
  TriMesh mesh_;
  std::vector<Positions> frames_;
  std::string label_;
};

/// Parameters of the built-in folding sequence (see `FoldingSequence`).
struct FoldingParams {
  Index n = 24;             ///< lattice resolution: n × n quads over the unit square, edge ℓ = 1/n
  std::size_t frames = 60;  ///< number of frames
  std::uint64_t seed = 1;   ///< phases and frequencies of the ripple, per-vertex jitter
};

/// A seeded, deterministic deforming sequence with growing self-contact, standing in for the
/// thesis' hanging cloth without collision response until the simulator exists.
///
/// The unit-square n × n lattice is folded along x = 1/2: the half x > 1/2 wraps around a
/// cylinder of radius R = 1.5ℓ and continues straight, at a fold angle θ that grows linearly
/// from 0.8π (frame 0, layers apart) to 1.15π (last frame: the upper layer tilts through the
/// lower one). The upper layer carries a travelling ripple of amplitude up to 3.3R towards the
/// lower layer (frequencies and phases from the seed), so contacts appear in patches, move and
/// spread; every vertex has a fixed seeded jitter of 0.02ℓ. Suggested thickness: ℓ/4 (below
/// the smallest distance between non-adjacent elements of the flat lattice, ℓ/√2).
class FoldingSequence final : public FrameSource {
 public:
  explicit FoldingSequence(FoldingParams params = {});
  std::size_t size() const override { return params_.frames; }
  const TriMesh& mesh() const override { return mesh_; }
  Positions positions(std::size_t i) const override;
  std::string name(std::size_t i) const override;
  /// The suggested contact thickness, ℓ/4.
  Scalar thickness() const { return 0.25 / static_cast<Scalar>(params_.n); }
  const FoldingParams& params() const { return params_; }

 private:
  FoldingParams params_;
  TriMesh mesh_;
  std::vector<Vec3> jitter_;
  double k1_ = 0, k2_ = 0, phase1_ = 0, phase2_ = 0, speed_ = 0;
};

/// How a contact set matches a reference one.
struct ContactMatch {
  std::size_t reference = 0;       ///< contacts in the reference
  std::size_t found = 0;           ///< reference contacts also reported
  std::size_t missed = 0;          ///< reference contacts not reported
  std::size_t false_contacts = 0;  ///< reported contacts absent from the reference
  std::size_t reported = 0;        ///< contacts reported
  /// found / reference (1 when the reference is empty).
  double recall() const { return reference == 0 ? 1.0 : static_cast<double>(found) / reference; }
  /// found / reported (1 when nothing is reported).
  double precision() const { return reported == 0 ? 1.0 : static_cast<double>(found) / reported; }
  /// Adds another frame's counts (totals over a sequence).
  ContactMatch& operator+=(const ContactMatch& o) {
    reference += o.reference;
    found += o.found;
    missed += o.missed;
    false_contacts += o.false_contacts;
    reported += o.reported;
    return *this;
  }
};

/// Matches two contact sets by identity (both sorted canonically, as detectors return them).
ContactMatch match_contacts(const ContactSet& got, const ContactSet& reference);

/// One frame of a comparison.
struct FrameComparison {
  std::size_t frame = 0;
  std::string name;
  ContactMatch match;
  double ms = 0;            ///< the method's update time
  double reference_ms = 0;  ///< the reference's update time
  DetectorStats stats;      ///< the method's statistics for this frame
};

/// Totals over a sequence.
struct ComparisonSummary {
  std::size_t frames = 0;
  ContactMatch total;      ///< sums over frames (recall() is the overall recall)
  double min_recall = 1;   ///< worst frame
  double mean_ms = 0;
  double mean_reference_ms = 0;
};

/// The reference's contacts and times on every frame (to compare several methods against one
/// run of the reference).
struct ReferenceRun {
  std::vector<ContactSet> contacts;
  std::vector<double> ms;
};

/// Runs `reference` on every frame (topology set from `frames.mesh()`).
ReferenceRun run_reference(Detector& reference, const FrameSource& frames);

/// Runs `method` on every frame (topology set from `frames.mesh()`, frames fed in order with
/// the previous positions) and compares each frame with `reference`. `on_frame` is called after
/// each frame.
ComparisonSummary compare_detectors(Detector& method, const ReferenceRun& reference,
                                    const FrameSource& frames,
                                    const std::function<void(const FrameComparison&)>& on_frame = {});

/// Same, running the reference frame by frame.
ComparisonSummary compare_detectors(Detector& method, Detector& reference, const FrameSource& frames,
                                    const std::function<void(const FrameComparison&)>& on_frame = {});

}  // namespace crumple
