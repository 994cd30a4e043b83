#pragma once
/// \file
/// Internal to the exact detector: what the narrow-phase stages share during one frame
/// (`NarrowFrame`), and their entry points. Every sub-pair reaches the exact kernels of
/// detect/narrow_phase.hpp (the ones `naive` calls, with the same argument order, so the
/// distances are the same bits) only past cheap rejections that never drop a pair within the
/// padded thickness: a box test in float lanes (float_lanes.hpp), then a plane or line
/// separation test (geometry/separation.hpp).

#include <crumple/core/frame_deadline.hpp>
#include <crumple/detect/broad_phase/broad_phase.hpp>
#include <crumple/detect/contact.hpp>
#include <crumple/detect/exact/float_lanes.hpp>
#include <crumple/detect/exact/orphans.hpp>
#include <crumple/detect/gather.hpp>
#include <crumple/detect/narrow_phase.hpp>
#include <crumple/geometry/separation.hpp>

#include <array>
#include <atomic>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <mutex>
#include <span>
#include <type_traits>
#include <vector>

namespace crumple::exact {

/// What the narrow phase reads of one face's topology, in one 32-byte record, so that a
/// candidate pair touches two cache lines. The corners' positions are read from the frame's
/// positions and their float roundings from `NarrowFrame::coarse_x`.
struct alignas(32) PackedFace {
  Face v;                        ///< corner ids
  std::array<Index, 3> e;        ///< side ids (side k joins corners k and k+1)
  std::uint8_t vertex_mask = 0;  ///< bit k: this face owns corner k
  std::uint8_t edge_mask = 0;    ///< bit k: this face owns side k
};
static_assert(sizeof(PackedFace) == 32);

using crumple::storage_bytes;
inline std::size_t storage_bytes(const ContactSet& s) {
  return storage_bytes(s.vf) + storage_bytes(s.ee) + storage_bytes(s.tt);
}

/// Contacts found by one chunk of the narrow phase, each with its key (its place in canonical
/// order, for `detail::gather_sorted`): records kept with their keys, and keys alone, whose
/// records the gather makes again (`NarrowFrame::keep_budget`).
struct KeyedContacts {
  ContactSet set;
  std::vector<std::uint64_t> vf_keys, ee_keys, tt_keys;  ///< of set's records
  std::vector<std::uint64_t> vf_only, ee_only, tt_only;  ///< records not kept
  void clear() {
    set.clear();
    for (auto* keys : {&vf_keys, &ee_keys, &tt_keys, &vf_only, &ee_only, &tt_only}) keys->clear();
  }
  bool empty() const {
    return set.empty() && vf_only.empty() && ee_only.empty() && tt_only.empty();
  }
};
inline std::size_t storage_bytes(const KeyedContacts& c) {
  return storage_bytes(c.set) + storage_bytes(c.vf_keys) + storage_bytes(c.ee_keys) + storage_bytes(c.tt_keys) +
         storage_bytes(c.vf_only) + storage_bytes(c.ee_only) + storage_bytes(c.tt_only);
}

/// Contacts found by one chunk of work, kept until the frame's set is gathered.
struct LocalContacts {
  explicit LocalContacts(KeyedContacts&& spare) : keyed(std::move(spare)) {}
  KeyedContacts keyed;  ///< the contacts found so far, with their keys
  /// Contacts not listed yet: `NarrowFrame::spill` lists them every `kSpill` or so.
  ContactSet set;
  std::size_t vf_tests = 0, ee_tests = 0, tt_tests = 0;
  narrow::VertexFaceBatch vf_batch;        ///< vertex-face pairs queued for the kernel, four at a time
  narrow::EdgeEdgeBatch ee_batch;          ///< edge pairs queued for the kernel, four at a time
  narrow::TriangleTriangleBatch tt_batch;  ///< face pairs queued for the intersection test
};

/// `LocalContacts::set` holds about this many contacts at most (plus a batch's four).
inline constexpr std::size_t kSpill = 256;
/// `NarrowFrame::keep_budget` per face of the mesh: records below it are copied by the gather,
/// above it made again by their kernel (one more kernel call per contact).
inline constexpr std::size_t kKeepBytesPerFace = 512;

/// Sub-pairs are taken in blocks: the block's sub-pairs are listed (as 16-bit codes), the
/// rejections sift the list, and the exact kernels run over what is left.
inline constexpr std::size_t kBlock = 64;
using CodeList = std::array<std::uint16_t, kBlock>;

/// Lists the codes 0 .. n-1 (a sub-pair's place in its block).
inline void iota(CodeList& list, std::size_t n) {
  for (std::size_t k = 0; k < n; ++k) list[k] = static_cast<std::uint16_t>(k);
}

/// Keeps, in order, the codes of list[0, n) for which keep(code) holds; returns their number.
/// Branch-free: which sub-pairs pass a rejection test is unpredictable.
template <class Keep>
std::size_t sift(std::uint16_t* list, std::size_t n, const Keep& keep) {
  std::size_t kept = 0;
  for (std::size_t s = 0; s < n; ++s) {
    const std::uint16_t code = list[s];
    list[kept] = code;
    kept += keep(code) ? 1u : 0u;
  }
  return kept;
}

#if CRUMPLE_SEPARATION_LANES
/// Keeps, in order, the codes of list[0, n) that the plane (kLine false) or line (kLine true)
/// test of their points(code) (`geometry::SeparationPoints`) leaves within pad, four at a time
/// (`geometry::beyond_x4`); returns their number. Compiled for AVX2: only where the CPU has it.
template <bool kLine, class Points>
__attribute__((target("avx2"))) std::size_t sift_separated_x4(std::uint16_t* list, std::size_t n, Scalar pad,
                                                              const Points& points) {
  std::size_t kept = 0;
  for (std::size_t s = 0; s < n; s += 4) {
    std::array<std::uint16_t, 4> code;
    std::array<geometry::SeparationPoints, 4> at;
    for (std::size_t l = 0; l < 4; ++l) {
      code[l] = list[std::min(s + l, n - 1)];  // past the end, the last code again (not kept)
      at[l] = points(code[l]);
    }
    const unsigned beyond = geometry::beyond_x4<kLine>(at, pad);
    for (std::size_t l = 0; l < std::min<std::size_t>(4, n - s); ++l) {
      list[kept] = code[l];
      kept += (beyond >> l & 1u) ^ 1u;
    }
  }
  return kept;
}
#endif

/// The gap between the boxes of edges (p0, p1) and (q0, q1) (negative if they overlap), as a
/// lower bound of their distance (rounded down by 1e-12 of itself).
inline Scalar edge_box_gap(const Vec3& p0, const Vec3& p1, const Vec3& q0, const Vec3& q1) {
  Scalar gap = -std::numeric_limits<Scalar>::infinity();
  for (int a = 0; a < 3; ++a) {
    const auto [lo0, hi0] = std::minmax(p0[a], p1[a]);
    const auto [lo1, hi1] = std::minmax(q0[a], q1[a]);
    gap = std::max({gap, lo1 - hi0, lo0 - hi1});
  }
  return gap * (1 - 1e-12);
}

/// One frame of the narrow phase: its inputs, the tests shared by its stages, and the
/// contacts the stages' chunks hand in (`collect`).
///
/// One padding quantity: `pad`, the padded thickness (exact_detector.hpp): no rejection drops
/// a sub-pair within `pad`, and the broad phase inflates each face by `pad / 2`. Its float
/// versions `float_pad` and `float_half_pad` (`coarse_pad`) cover the rounding of the float
/// lanes, or are infinite (no box rejects) when the coordinates are beyond floats.
struct NarrowFrame {
  NarrowFrame(const Topology& topo, PositionsView x, ContactKinds kinds, int threads, Scalar thickness, Scalar pad,
              Scalar magnitude, const std::vector<PackedFace>& packed,
              const std::vector<std::array<Vec3, 3>>& face_corners, const std::vector<std::array<float, 4>>& coarse_x,
              const std::vector<Index>& edge_rank, Spares<KeyedContacts>& spares);

  const Topology& topo;
  PositionsView x;
  ContactKinds kinds;
  bool proximity;  ///< VF or EE asked
  int threads;
  Scalar thickness;      ///< h: a contact is closer than h
  Scalar sqr_thickness;  ///< h^2, what the kernels compare squared distances with
  Scalar pad;            ///< the padded thickness
  float float_half_pad, float_pad;
#if CRUMPLE_SEPARATION_LANES
  bool avx2;  ///< the separation tests run four at a time
#endif
  const std::vector<PackedFace>& packed;
  /// Per face, its corners side by side (filled on the frames that ask for intersections,
  /// whose test reads all six corners of every candidate).
  const std::vector<std::array<Vec3, 3>>& face_corners;
  /// Per vertex, this frame's position rounded to float (then 0); filled when proximity is
  /// asked.
  const std::vector<std::array<float, 4>>& coarse_x;
  const std::vector<Index>& edge_rank;  ///< each edge's rank in (first, second vertex) order
  Spares<KeyedContacts>& spares;

  /// Bytes of records the chunks may keep beside their keys (`kKeepBytesPerFace` a face); the
  /// records of the others are made again from their keys by the gather, so that a frame
  /// never holds its records twice beyond this.
  std::size_t keep_budget;
  mutable std::atomic<std::size_t> kept{0};  ///< bytes of records kept so far

  std::mutex mutex;  ///< guards the members below
  std::vector<KeyedContacts> parts;  ///< each chunk's contacts, gathered in order at the end
  std::size_t vf_tests = 0, ee_tests = 0, tt_tests = 0;

  /// Flushes a chunk's queued tests, lists its contacts' keys and hands them in.
  void collect(LocalContacts& local);
  /// Lists the keys of the contacts in local.set, keeps their records while the frame's kept
  /// records stay within `keep_budget`, and empties local.set.
  void list_keys(LocalContacts& local) const;
  /// `list_keys` once local.set holds `kSpill` contacts: past the budget, a chunk holds its
  /// contacts' keys, not their records.
  void spill(LocalContacts& local) const {
    if (local.set.vf.size() + local.set.ee.size() + local.set.tt.size() >= kSpill) list_keys(local);
  }

  /// Corner k of face t, at x.
  const Vec3& corner(const PackedFace& t, std::size_t k) const { return narrow::at(x, t.v[k]); }
  F4 coarse_point(Index v) const { return load4(coarse_x[static_cast<std::size_t>(v)]); }

  /// Vertex v at p against face g, past the cheap rejections: the shared kernel, queued four
  /// at a time (the contacts reach local.set.vf at the latest in `collect`), unless the squared
  /// distance is wanted.
  void vf_kernel(const Vec3& p, Index v, const Vec3& a, const Vec3& b, const Vec3& c, Index g, LocalContacts& local,
                 Scalar* sqr_distance = nullptr) const {
    ++local.vf_tests;
    if (sqr_distance == nullptr) {
      local.vf_batch.push(v, p, g, a, b, c, sqr_thickness, local.set.vf);
    } else if (auto contact = narrow::vertex_face(v, p, g, a, b, c, sqr_thickness, sqr_distance)) {
      local.set.vf.push_back(*contact);
    }
    spill(local);
  }
  /// Edge e0 = (p0, p1) of vertices (u0, u1) and edge e1 = (q0, q1) of vertices (w0, w1), each
  /// in any order, past the cheap rejections: the shared kernel, which sees the edges as the
  /// mesh stores them (lower id first, each from its lower vertex), as for every other
  /// detector. Queued four at a time, unless the squared distance is wanted.
  void ee_kernel(const Vec3& p0, const Vec3& p1, Index u0, Index u1, Index e0, const Vec3& q0, const Vec3& q1,
                 Index w0, Index w1, Index e1, LocalContacts& local, Scalar* sqr_distance = nullptr) const {
    ++local.ee_tests;
    if (sqr_distance == nullptr) {
      local.ee_batch.push(e0, u0, u1, p0, p1, e1, w0, w1, q0, q1, sqr_thickness, local.set.ee);
    } else if (auto c = narrow::EdgePair::ordered(e0, u0, u1, p0, p1, e1, w0, w1, q0, q1).test(sqr_thickness, sqr_distance)) {
      local.set.ee.push_back(*c);
    }
    spill(local);
  }

  /// The box of face t padded by `pad` holds p (branch-free; NaN: it does not).
  bool in_box(const Vec3& p, const PackedFace& t) const {
    const Vec3 &a = corner(t, 0), &b = corner(t, 1), &c = corner(t, 2);
    bool outside = false;
    for (int i = 0; i < 3; ++i) {
      outside |= int(!(std::min({a[i], b[i], c[i]}) - pad <= p[i])) | int(!(p[i] <= std::max({a[i], b[i], c[i]}) + pad));
    }
    return !outside;
  }
  /// The gap between p and the box of face t (negative inside), as a lower bound of their
  /// distance (rounded down by 1e-12 of itself).
  Scalar vertex_box_gap(const Vec3& p, const PackedFace& t) const {
    const Vec3 &c0 = corner(t, 0), &c1 = corner(t, 1), &c2 = corner(t, 2);
    Scalar gap = -std::numeric_limits<Scalar>::infinity();
    for (int a = 0; a < 3; ++a) {
      gap = std::max({gap, std::min({c0[a], c1[a], c2[a]}) - p[a], p[a] - std::max({c0[a], c1[a], c2[a]})});
    }
    return gap * (1 - 1e-12);
  }

  /// Sifts list[0, n) by the plane (kLine false) or line (kLine true) separation test of
  /// points(code) (`geometry::SeparationPoints`) against `pad`: four codes at a time in AVX2
  /// lanes where the CPU has them (the same verdicts).
  template <bool kLine, class Points>
  std::size_t sift_separated(std::uint16_t* list, std::size_t n, const Points& points) const {
#if CRUMPLE_SEPARATION_LANES
    if (avx2) return sift_separated_x4<kLine>(list, n, pad, points);
#endif
    return sift(list, n, [&](std::uint16_t code) {
      const geometry::SeparationPoints q = points(code);
      return !geometry::beyond(kLine ? geometry::line_separation(*q[0], *q[1], *q[2], *q[3])
                                     : geometry::plane_separation(*q[0], *q[1], *q[2], *q[3]),
                               pad);
    });
  }
  /// The cheap rejections of a list of vertex-face sub-pairs, in order, leaving those the
  /// kernel must test: point(code) gives the vertex's position and face(code) the face.
  template <class Point, class FaceOf>
  std::size_t sift_vertex_face(std::uint16_t* list, std::size_t n, const Point& point, const FaceOf& face) const {
    n = sift(list, n, [&](std::uint16_t code) { return in_box(point(code), face(code)); });
    return sift_separated<false>(list, n, [&](std::uint16_t code) {
      const PackedFace& t = face(code);
      return geometry::SeparationPoints{&point(code), &corner(t, 0), &corner(t, 1), &corner(t, 2)};
    });
  }
};

/// Stage: the sub-pairs of the broad phase's candidates (faces sharing no vertex), each tested
/// in the one pair of its owners (ownership.hpp), by kind: VF, EE, TT.
void narrow_candidates(NarrowFrame& frame, const CandidateBuffer& candidates);
/// The same stage over one chunk of candidates as a streaming broad phase hands it in
/// (`CandidateBuffer::set_consumer`), on the calling thread; callable concurrently.
void narrow_candidate_chunk(NarrowFrame& frame, std::span<const FacePair> chunk);

/// The budget of a cut-off frame (`ExactParams::budget_ms`, `pairs`): candidates are claimed
/// before they are tested, a block at a time; once the budget is spent, nothing more is.
/// Thread-safe (with a wall-clock deadline). With a pair limit only, the cut depends on the
/// candidates' order alone.
class Cutoff {
 public:
  /// At most `pairs` candidates (0: no limit), and none claimed once less than `reserve_ms` of
  /// `deadline`'s budget is left (the stages after the cut-off's: `FrameDeadline::passed`).
  Cutoff(std::size_t pairs, const FrameDeadline& deadline, double reserve_ms = 0)
      : limit_(pairs), deadline_(deadline), reserve_ms_(reserve_ms) {}
  /// Claims up to n candidates: returns how many may be tested (0 once the budget is spent).
  std::size_t claim(std::size_t n) {
    if (spent_.load(std::memory_order_relaxed) || n == 0) return 0;
    if (deadline_.passed(reserve_ms_)) {
      mark_spent();
      return 0;
    }
    std::size_t take = n;
    if (limit_ != 0) {
      const std::size_t before = claimed_.fetch_add(n, std::memory_order_relaxed);
      take = before >= limit_ ? 0 : std::min(n, limit_ - before);
      if (take < n) mark_spent();
    }
    tested_.fetch_add(take, std::memory_order_relaxed);
    return take;
  }
  /// True once a claim was refused, or (when timed) the deadline has passed.
  bool spent() {
    if (!spent_.load(std::memory_order_relaxed) && deadline_.passed(reserve_ms_)) mark_spent();
    return spent_.load(std::memory_order_relaxed);
  }
  /// Candidates granted so far.
  std::size_t tested() const { return tested_.load(std::memory_order_relaxed); }
  /// Whether a stage of `cost_ms` that runs whole may start: the budget is not spent, and
  /// `cost_ms` more still leaves the reserve.
  bool fits(double cost_ms) {
    if (spent()) return false;
    return !deadline_.passed(reserve_ms_ + cost_ms);
  }
  const FrameDeadline& deadline() const { return deadline_; }
  /// When the budget was first found spent, on the deadline's clock (`now_ms`); < 0: not yet.
  double spent_at_ms() const { return spent_at_ms_.load(std::memory_order_relaxed); }

 private:
  std::size_t limit_;
  const FrameDeadline& deadline_;
  void mark_spent() {
    if (!spent_.exchange(true, std::memory_order_relaxed)) spent_at_ms_.store(deadline_.now_ms(), std::memory_order_relaxed);
  }

  double reserve_ms_;
  std::atomic<double> spent_at_ms_{-1};
  std::atomic<std::size_t> claimed_{0}, tested_{0};
  std::atomic<bool> spent_{false};
};

/// Stage, cut off: the candidates of one streamed chunk, claimed from `cut` a block at a time
/// (serially, in the calling thread). Returns false when the budget stopped it.
bool narrow_candidates(NarrowFrame& frame, std::span<const FacePair> chunk, Cutoff& cut);

/// Stage: the orphan sub-pairs (orphans.hpp) of the awake blocks; on a `refresh`, every block,
/// whose distance bound is then set from what its tests compute anyway. Returns the number of
/// blocks tested.
std::size_t narrow_orphans(NarrowFrame& frame, Orphans& orphans, bool refresh);

/// Stage: the orphan sub-pairs whose source is a star (orphans.hpp), found among the pairs of
/// its faces whose boxes meet, inflated by pad / 2 (narrow_stars.cpp). Returns the number of
/// face pairs examined.
std::size_t narrow_stars(NarrowFrame& frame, const std::vector<Index>& stars, const FeatureOwnership& own);

/// Stage: vertices used by no face against the faces whose boxes come within pad.
void narrow_isolated(NarrowFrame& frame, const std::vector<Index>& isolated);

/// Scratch buffers of `gather_contacts`, kept across frames.
struct GatherBuffers {
  detail::GatherScratch main;   ///< of the edge-edge contacts (or every kind, one after the other)
  detail::GatherScratch other;  ///< of the vertex-face and triangle contacts', placed beside them
};

/// Stage: the frame's contacts, from the chunks' `frame.parts`, into `out` in canonical order:
/// kept records copied, the others made again from their keys by the kernel that found them
/// (the same bits). Each kind's keys are freed once its places are found, before `out` is
/// sized; the parts' storage goes back to `frame.spares`. `edge_by_rank` inverts `edge_ranks`.
void gather_contacts(NarrowFrame& frame, const std::vector<Index>& edge_by_rank, GatherBuffers& buffers,
                     ContactSet& out);

/// Each edge's rank in (first vertex, second vertex) order: the key of the edge-edge gather.
std::vector<Index> edge_ranks(const Topology& topo);

}  // namespace crumple::exact
