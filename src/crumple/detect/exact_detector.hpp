#pragma once
/// \file
/// The exact pipeline shared by the `kdop`, `hash` and `sap` detectors (docs/exact-detectors.md):
///
///  1. broad phase (per method): every unordered pair of faces that share no vertex and whose
///     boxes, inflated by `FrameInput::radius` (half the padded thickness) on every side,
///     overlap — emitted exactly once (a broad phase may also emit pairs whose boxes are
///     apart by less than a float rounding: the narrow phase rejects them; and, for a
///     proximity query, it may leave out pairs that own no sub-pair, `FrameInput::owns`);
///  2. orphans: pairs of faces that share a vertex are never emitted by a broad phase; their
///     vertex–face and edge–edge sub-pairs that are *not* excluded (the vertex opposite a
///     shared edge, edges around a shared vertex) are listed once per topology and tested
///     every frame (Tang et al.'s orphan sets);
///  3. narrow phase: each sub-pair is tested in exactly one place thanks to feature ownership
///     ("representative triangles", Curtis, Tamstorf & Manocha 2008): every vertex and every
///     edge is owned by one of its incident faces, chosen so that many faces own no vertex and
///     many no edge (`ExactDetector::on_topology`; a pair of faces that owns no sub-pair is then
///     left out of a proximity query's broad phase); VF (v, g) is tested only in the pair
///     {owner(v), g}, EE (e1, e2) only in {owner(e1), owner(e2)}. This is exact: a face's
///     inflated box holds its features inflated by the same radius, so a sub-pair closer than
///     h always lies in an overlapping owner pair. Cheap rejections (vertex against face box,
///     edge box against edge box) run before the exact kernels of narrow_phase.hpp, which are
///     the ones `naive` calls with the same argument order, so distances are bit-identical;
///  4. isolated vertices (used by no face) are tested against every face box.
///
/// Rounding: all boxes are padded by `h (1 + 1e-6) + 1e-9 M` (M = largest coordinate
/// magnitude of the frame) rather than h, so a pair the kernels place just under h is never
/// rejected by a box test evaluated in different arithmetic. When only TT is asked, the
/// thickness plays no part and the pad is the rounding margin alone.

#include <crumple/core/error.hpp>
#include <crumple/detect/broad_phase/broad_phase.hpp>
#include <crumple/detect/detector.hpp>
#include <crumple/detect/gather.hpp>

#include <algorithm>
#include <array>
#include <cstddef>
#include <limits>
#include <memory>
#include <mutex>
#include <span>
#include <utility>
#include <vector>

namespace crumple {

/// Thrown by an exact detector when the contacts of a frame exceed `max_contacts` and
/// `overflow=error` (the default).
class ContactOverflowError : public Error {
 public:
  using Error::Error;
};

/// Keys common to the exact detectors (`max_contacts`, `overflow`).
struct ExactParams {
  std::size_t max_contacts = 0;  ///< cap on the contacts of one frame; 0 = no cap
  bool overflow_error = true;    ///< over the cap: throw (true) or keep the first contacts
  static ExactParams from_spec(const MethodSpec& spec);
  bool operator==(const ExactParams&) const = default;
};

inline std::size_t storage_bytes(const ContactSet& s) {
  return storage_bytes(s.vf) + storage_bytes(s.ee) + storage_bytes(s.tt);
}

/// Contacts found by one chunk of the narrow phase, each list with its records' keys (their
/// places in canonical order, for `detail::gather_sorted`).
struct KeyedContacts {
  ContactSet set;
  std::vector<std::uint64_t> vf_keys, ee_keys, tt_keys;
  void clear() {
    set.clear();
    vf_keys.clear();
    ee_keys.clear();
    tt_keys.clear();
  }
};
inline std::size_t storage_bytes(const KeyedContacts& c) {
  return storage_bytes(c.set) + storage_bytes(c.vf_keys) + storage_bytes(c.ee_keys) + storage_bytes(c.tt_keys);
}

/// The exact detector: the pipeline above over the candidates of a broad phase it owns
/// (`kdop`, `hash` or `sap`, whichever is given; make_detector.cpp picks it from the spec).
class ExactDetector final : public Detector {
 public:
  ExactDetector(DetectorOptions options, ExactParams params, std::unique_ptr<BroadPhase> broad_phase);
  ~ExactDetector() override;
  Method method() const override { return broad_phase_->method(); }
  const BroadPhase& broad_phase() const { return *broad_phase_; }
  const BoundingHierarchy* hierarchy() const override { return broad_phase_->hierarchy(); }
  /// True when the last frame had more contacts than `max_contacts` (also in stats:
  /// `overflow` = 1, `contacts_dropped`).
  bool overflowed() const { return overflowed_; }

 protected:
  /// The contacts are gathered in canonical order (`detail::gather_sorted`).
  bool sorted_output() const override { return true; }

 private:
  void on_topology() final;
  void detect(PositionsView previous, PositionsView positions, ContactSet& out) final;
  /// `magnitude`: the largest coordinate magnitude of the frame (or more).
  void narrow_phase(PositionsView x, Scalar pad, Scalar magnitude, const CandidateBuffer& candidates,
                    ContactSet& out);
  /// Marks the orphan blocks to test this frame (all of them on a refresh); returns whether
  /// this frame refreshes the blocks' bounds.
  bool wake_orphan_blocks(PositionsView x, Scalar pad, int threads);

  ExactParams params_;
  std::unique_ptr<BroadPhase> broad_phase_;
  bool overflowed_ = false;
  CandidateBuffer candidates_;
  /// (vertex, face) sub-pairs of adjacent faces, by face (then vertex): a run of one face's
  /// sub-pairs shares its box test's bounds.
  std::vector<std::array<Index, 2>> orphan_vf_;
  /// An orphan edge pair, first < second, with both edges' vertices (read without going
  /// through the topology's edge list, 1.5 M times a frame on n-body). By first edge (then
  /// second), so that a run of them shares the first edge's box.
  struct OrphanEdges {
    std::array<Index, 2> e;
    Edge a, b;
  };
  std::vector<OrphanEdges> orphan_ee_;
  /// Temporal coherence of the orphans (docs/exact-detectors.md). Each orphan list is cut into
  /// blocks of `kOrphanBlock` sub-pairs, each with the vertices its sub-pairs use and a lower
  /// bound of their distances at the positions of the last refresh (`orphan_ref_`). A block
  /// whose vertices have since moved, relative to its first one, by less than half its margin
  /// over the padded thickness cannot hold a contact and is skipped.
  static constexpr std::size_t kOrphanBlock = 64;
  struct OrphanBlocks {
    std::vector<std::size_t> begin;   ///< block b uses verts[begin[b], begin[b + 1])
    std::vector<Index> verts;         ///< sorted, distinct, per block
    std::vector<Scalar> bound;        ///< lower bound of the block's distances at orphan_ref_
    std::vector<std::uint8_t> awake;  ///< tested this frame
    /// Block b's sub-pairs are runs of one face (VF) or first edge (EE), of lengths
    /// runs[run_begin[b], run_begin[b + 1]).
    std::vector<std::size_t> run_begin;
    std::vector<std::uint8_t> runs;
    std::size_t size() const { return bound.size(); }
  };
  OrphanBlocks vf_blocks_, ee_blocks_;
  Positions orphan_ref_;  ///< positions of the last refresh; empty: none yet
  bool orphan_refreshed_ = false;  ///< the previous frame was a refresh
  int orphan_backoff_ = 0;         ///< frames to wait before the next refresh after one that did not pay
  int orphan_wait_ = 0;            ///< frames left to wait (every block tested meanwhile)
  std::vector<Index> isolated_;                  ///< vertices used by no face
  std::vector<std::uint8_t> face_owns_;          ///< per face: bit 0 owns a vertex, bit 1 an edge
  std::vector<Index> edge_rank_;                 ///< each edge's rank in (first, second vertex) order
  Spares<KeyedContacts> spare_sets_;             ///< per-chunk contacts and their keys, for reuse
  detail::GatherScratch gather_;  ///< buffers of the final gather, kept across frames
  detail::GatherScratch gather_other_;  ///< of the vertex-face and triangle contacts' beside it
  /// What the narrow phase reads of one face's topology, in one 32-byte record, so that a
  /// candidate pair touches two lines. The corners' positions are read from the frame's
  /// positions and their float roundings from `coarse_x_`. (The records held copies of both,
  /// written every frame: 120 bytes a face, 2.9 MB on armadillo, whose positions and float
  /// corners are 0.5 MB. Reading them in place changed the narrow phase, one thread, kdop:
  /// armadillo 4.3-4.6 -> 4.0-4.1 ms, n-body 10.5 -> 8.8-9.1, funnel 3.5-3.6 -> 3.4, and the
  /// scenes with many candidates a face, whose corners then come from arrays past the L2
  /// cache: cloth-ball 68.0-68.3 -> 69.7-72.0, rod-twist 67.5-68.5 -> 69.7-71.2; `hash`, whose
  /// candidates come by cells, cloth-ball 106 -> 127-134. Copying the corners only on frames
  /// with more than two candidates a face did not win those back: kdop cloth-ball 71.4-74.6.)
  struct alignas(32) PackedFace {
    Face v;                        ///< corner ids
    std::array<Index, 3> e;        ///< side ids (side k joins corners k and k+1)
    std::uint8_t vertex_mask = 0;  ///< bit k: this face owns corner k
    std::uint8_t edge_mask = 0;    ///< bit k: this face owns side k
  };
  static_assert(sizeof(PackedFace) == 32);
  std::vector<PackedFace> packed_;
  /// Per face, its corners, copied on the frames that ask for intersections: the intersection
  /// test reads all six corners of every candidate, and from copies side by side cloth-ball's
  /// intersection-only narrow phase took 12.8-14.2 ms on one thread against 17.0-17.7 reading
  /// them in place.
  std::vector<std::array<Vec3, 3>> face_corners_;
  /// Per vertex, this frame's position rounded to float (then 0), for the box tests of the
  /// candidates and of the orphans, in float lanes; made by `detect` on frames that ask for
  /// proximity, in its pass for the frame's magnitude.
  std::vector<std::array<float, 4>> coarse_x_;
};

}  // namespace crumple
