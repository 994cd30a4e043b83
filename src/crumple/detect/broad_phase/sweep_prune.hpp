#pragma once
/// \file
/// `sap`: sweep and prune with insertion sort across frames (Cohen, Lin, Manocha & Ponamgi,
/// I-COLLIDE, I3D 1995), a broad phase
/// (broad_phase.hpp) of the exact detector.
///
/// The face boxes (current positions — for a continuous query, both ends of the step —
/// inflated by half the padded thickness) are kept sorted
/// by their lower end along one axis — the axis of largest centroid spread, chosen at the
/// first frame. The order persists across frames and is restored by insertion sort, O(n +
/// swaps) under temporal coherence (falls back to a full sort when the swaps exceed 32 n,
/// e.g. after a teleport). The sweep then scans, for each box, the boxes that start before it
/// ends on that axis and checks the two other axes: every overlapping pair is found once,
/// from its earlier box. Ties: closed intervals (touching boxes overlap), and the sort key is
/// (lower end, face id), so the initial sort and the insertion sort agree. The sweep runs in
/// parallel over boxes; the insertion sort is serial.
/// Spec: `sap:axis=auto|x|y|z` plus `max_contacts`, `overflow`.

#include <crumple/detect/broad_phase/broad_phase.hpp>

#include <vector>

namespace crumple {

struct SapParams {
  int axis = -1;  ///< 0, 1, 2, or -1 = automatic
  static SapParams from_spec(const MethodSpec& spec);
  bool operator==(const SapParams&) const = default;
};

class SweepPrune final : public BroadPhase {
 public:
  explicit SweepPrune(SapParams params);
  Method method() const override { return Method::Sap; }
  void build(const Topology& topology) override;
  void update(const FrameInput& in, DetectorStats& stats) override;
  void self_pairs(CandidateBuffer& out, DetectorStats& stats) override;

 private:
  SapParams params_;
  const Topology* topo_ = nullptr;
  int threads_ = 0;  ///< of the last update
  int axis_ = -1;
  std::vector<Box> boxes_;
  std::vector<Index> order_;        ///< faces sorted by (lower end on axis_, id)
  std::vector<Scalar> keys_;        ///< lower ends in `order_`
  std::vector<Box> sorted_boxes_;   ///< boxes in `order_`
  std::vector<Face> sorted_faces_;  ///< corners in `order_`
};

}  // namespace crumple
