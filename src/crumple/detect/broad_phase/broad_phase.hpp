#pragma once
/// \file
/// The broad-phase layer: structures that, given a mesh's faces and one frame's positions,
/// list the pairs of faces that may hold a contact. The exact detector (exact_detector.hpp)
/// takes one and runs its narrow phase over the pairs; a broad phase can also be used and
/// tested on its own (tests/detect/broad_phase_test.cpp checks each against brute force).
///
/// Lifecycle (the detector's, STYLE.md §3): `build` once per topology, then per frame
/// `update` (positions, optionally previous positions, an inflation radius) and `self_pairs`.
/// Two virtual calls per frame, none per pair: candidates are written in chunks to a
/// `CandidateBuffer`.
///
/// Contract of `self_pairs` (what the exact pipeline's proof relies on): every unordered pair
/// of faces that share no vertex and lie within 2 `FrameInput::radius` of each other (their
/// volumes swept by a ball of that radius meet) is emitted exactly once, as {min, max}; with
/// `FrameInput::intersection_only`, every such pair that intersects. `HashGrid` and
/// `SweepPrune` emit more: every pair whose boxes, inflated by the radius, overlap; `KdopTree`'s
/// k-DOPs are tighter than those boxes. Any broad phase may also emit pairs farther apart (by
/// a float rounding, or a frame-to-frame cache's slack: the narrow phase rejects them), and,
/// when `FrameInput::owns` is given, may leave out pairs of which neither face owns a vertex
/// and not both own an edge.
///
/// Continuous queries (`FrameInput::continuous`, detect/continuous.hpp): every face moves
/// linearly from `previous` to `positions`, and the contract holds for the volumes the faces
/// sweep over the whole step: every pair sharing no vertex whose swept volumes, each grown by
/// `radius`, meet is emitted. All three broad phases then bound each face by its corners at
/// both ends of the step (a point of a linearly moving face stays in the convex hull of those
/// six corners) and drop their current-position filters.
///
/// Streaming: a `CandidateBuffer` with a consumer hands each chunk to it as the chunk is
/// added, in the adding thread, instead of keeping it; emitters call `flush_if_full` between
/// units of work, so the candidates in memory are bounded by the chunks in flight. A consumer
/// may ask the emitters to stop (`stop`, a budget spent): they then return early, and the
/// candidates are incomplete; `KdopTree` checks between its traversal tasks, the others ignore it.

#include <crumple/core/types.hpp>
#include <crumple/detect/detector.hpp>
#include <crumple/detect/hierarchy.hpp>
#include <crumple/detect/method.hpp>
#include <crumple/mesh/mesh.hpp>

#include <algorithm>
#include <array>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <limits>
#include <memory>
#include <mutex>
#include <span>
#include <vector>

namespace crumple {

/// A broad-phase candidate: two faces sharing no vertex, `[0] < [1]`.
using FacePair = std::array<Index, 2>;

/// Per-frame input of a broad phase. The spans must stay valid until `self_pairs` returns.
struct FrameInput {
  PositionsView previous;  ///< empty when no motion is given
  PositionsView positions;
  Scalar radius = 0;  ///< inflate every face box by this on each side
  int threads = 0;    ///< worker threads: 0 = all hardware threads, 1 = serial
  /// Only intersections (TT) are asked: no proximity, so a patch that provably cannot
  /// intersect itself may be skipped (normal-cone culling, kdop_tree.hpp).
  bool intersection_only = false;
  /// Per face, what it owns (exact_detector.hpp, feature ownership): bit 0 a vertex, bit 1 an
  /// edge. Given when only proximity (VF, EE) is asked, empty otherwise: then a pair of faces
  /// of which neither owns a vertex and not both own an edge holds no sub-pair, and a broad
  /// phase may leave it out.
  std::span<const std::uint8_t> owns;
  /// A continuous query: `previous` is given and the candidates must cover each face's whole
  /// motion (file comment). `kdop` then sweeps whatever its `sweep` parameter says.
  bool continuous = false;
};

/// Bytes of storage a container holds (what `Spares` hands out first).
template <class U>
std::size_t storage_bytes(const std::vector<U>& v) {
  return v.capacity() * sizeof(U);
}

/// Cleared containers (anything with `clear()` and `storage_bytes`) kept for reuse, thread-safe:
/// a frame fills millions of candidates and tens of MB of contacts, and fresh allocations of
/// that size cost page faults.
template <class T>
class Spares {
 public:
  /// An empty container, with the largest storage given back earlier when there is one: a
  /// frame's first takers hold most of its data, and a small container handed to one of them
  /// would grow into fresh pages.
  T take() {
    const std::lock_guard lock(mutex_);
    if (spare_.empty()) return {};
    const auto largest = std::max_element(spare_.begin(), spare_.end(), [](const T& a, const T& b) {
      return storage_bytes(a) < storage_bytes(b);
    });
    T x = std::move(*largest);
    *largest = std::move(spare_.back());
    spare_.pop_back();
    return x;
  }
  /// Keeps x's storage for `take` (x is cleared).
  void give(T&& x) {
    x.clear();
    const std::lock_guard lock(mutex_);
    spare_.push_back(std::move(x));
  }

 private:
  std::mutex mutex_;
  std::vector<T> spare_;
};

/// Thread-safe sink of candidate chunks (each task appends its own vector once, or, when
/// streaming, whenever `flush_if_full` finds it full).
class CandidateBuffer {
 public:
  /// Receives a chunk of candidates; called concurrently from the broad phase's threads.
  using Consumer = std::function<void(std::span<const FacePair>)>;
  /// Chunks handed to a consumer hold about this many candidates (`flush_if_full`).
  static constexpr std::size_t kStreamChunk = std::size_t{1} << 14;

  /// An empty chunk to fill, reusing the storage of a cleared one when there is some.
  std::vector<FacePair> take() { return spares_.take(); }
  void add(std::vector<FacePair>&& chunk) {
    if (chunk.empty()) {
      if (chunk.capacity() > 0) spares_.give(std::move(chunk));
      return;
    }
    if (consumer_) {
      {
        const std::lock_guard lock(mutex_);
        total_ += chunk.size();
      }
      consumer_(chunk);  // an exception leaves the chunk to be freed; the loop rethrows it
      spares_.give(std::move(chunk));
      return;
    }
    const std::lock_guard lock(mutex_);
    total_ += chunk.size();
    chunks_.push_back(std::move(chunk));
  }
  /// Streams: every chunk added from now on goes to `consumer` and is not kept (`chunks()`
  /// stays empty; `total()` still counts), emitted in chunks of about `chunk` candidates (1:
  /// whatever an emitter has between its units of work). An empty function stops streaming.
  /// Clears a `stop`. With `resume`, an emitter that was stopped last frame may begin this one
  /// where it stopped (`KdopTree`: at the first task it left out), so that frames cut short
  /// cover the whole mesh in turn.
  /// `poll`, when given, is asked now and then by emitters that stream finely (chunk 1) whether
  /// to stop, between chunks too (`poll`): the work between two candidates is unbounded.
  void set_consumer(Consumer consumer, std::size_t chunk = kStreamChunk, bool resume = false,
                    std::function<bool()> poll = {}) {
    consumer_ = std::move(consumer);
    poll_ = std::move(poll);
    stream_chunk_ = chunk;
    resume_ = resume;
    stop_.store(false, std::memory_order_relaxed);
  }
  /// Asks the consumer's `poll` whether to stop (stopping the stream when it says so); returns
  /// `stopped()`. Thread-safe when `poll` is.
  bool poll() {
    if (!stopped() && poll_ && poll_()) stop();
    return stopped();
  }
  bool resuming() const { return resume_; }
  bool streaming() const { return static_cast<bool>(consumer_); }
  /// The chunk size `set_consumer` was given (meaningful while streaming).
  std::size_t stream_chunk() const { return stream_chunk_; }
  /// Asks the emitters to add nothing more this frame (thread-safe; a consumer calls it).
  void stop() { stop_.store(true, std::memory_order_relaxed); }
  bool stopped() const { return stop_.load(std::memory_order_relaxed); }
  /// When streaming and `chunk` holds at least the consumer's chunk size, adds it and replaces
  /// it by an empty one; otherwise does nothing (a kept chunk is not split).
  void flush_if_full(std::vector<FacePair>& chunk) {
    if (consumer_ && !chunk.empty() && chunk.size() >= stream_chunk_) {
      add(std::move(chunk));
      chunk = take();
    }
  }
  std::size_t total() const { return total_; }
  const std::vector<std::vector<FacePair>>& chunks() const { return chunks_; }
  /// Forgets the candidates, keeping the chunks' storage for `take`.
  void clear() {
    for (auto& chunk : chunks_) spares_.give(std::move(chunk));
    chunks_.clear();
    total_ = 0;
  }

 private:
  std::mutex mutex_;
  std::vector<std::vector<FacePair>> chunks_;
  Spares<std::vector<FacePair>> spares_;
  Consumer consumer_;
  std::function<bool()> poll_;
  std::size_t stream_chunk_ = kStreamChunk;
  bool resume_ = false;
  std::atomic<bool> stop_{false};
  std::size_t total_ = 0;
};

/// Axis-aligned box as two corners (plain arrays: the hot loops compare them directly).
struct Box {
  std::array<Scalar, 3> lo;
  std::array<Scalar, 3> hi;
  /// Closed intervals: touching boxes overlap. False when either box has a NaN side.
  /// Branch-free on purpose: the six comparisons as ints, ANDed bitwise (whether boxes overlap
  /// is unpredictable in the broad phases' loops).
  bool overlaps(const Box& o) const {
    return (int(lo[0] <= o.hi[0]) & int(o.lo[0] <= hi[0]) & int(lo[1] <= o.hi[1]) & int(o.lo[1] <= hi[1]) &
            int(lo[2] <= o.hi[2]) & int(o.lo[2] <= hi[2])) != 0;
  }
  /// Closed: a point on the boundary is inside. False for a NaN coordinate. Branch-free, as
  /// `overlaps`.
  bool contains(const Vec3& p) const {
    return (int(lo[0] <= p.x()) & int(p.x() <= hi[0]) & int(lo[1] <= p.y()) & int(p.y() <= hi[1]) &
            int(lo[2] <= p.z()) & int(p.z() <= hi[2])) != 0;
  }
  /// The empty box (lo = +inf, hi = -inf): `grow` and `merge` start from it, and keep a side as
  /// it is for a NaN coordinate.
  static Box empty() {
    constexpr Scalar inf = std::numeric_limits<Scalar>::infinity();
    return {{inf, inf, inf}, {-inf, -inf, -inf}};
  }
  void grow(const Vec3& p) {
    for (int i = 0; i < 3; ++i) {
      const auto k = static_cast<std::size_t>(i);
      lo[k] = std::min(lo[k], p[i]);
      hi[k] = std::max(hi[k], p[i]);
    }
  }
  void merge(const Box& o) {
    for (std::size_t k = 0; k < 3; ++k) {
      lo[k] = std::min(lo[k], o.lo[k]);
      hi[k] = std::max(hi[k], o.hi[k]);
    }
  }
  void inflate(Scalar r) {
    for (std::size_t k = 0; k < 3; ++k) {
      lo[k] -= r;
      hi[k] += r;
    }
  }
};

/// True when the faces share a vertex (9 comparisons).
inline bool faces_share_vertex(const Face& a, const Face& b) {
  int s = 0;  // branch-free: bitwise ors of the nine comparisons
  for (Index v : a) s |= int(v == b[0]) | int(v == b[1]) | int(v == b[2]);
  return s != 0;
}

/// Every face's box (current positions, and previous ones too when `sweep` and given; callers
/// pass `in.continuous` or their own sweep parameter),
/// inflated by `in.radius`; computed in parallel. A NaN corner is skipped (the box of the
/// face's finite corners); a face with all corners NaN has the empty box.
void face_boxes(const Topology& topo, const FrameInput& in, bool sweep, std::vector<Box>& out);

/// A broad phase over one topology. Implementations: `KdopTree`, `HashGrid`, `SweepPrune`.
class BroadPhase {
 public:
  BroadPhase() = default;
  virtual ~BroadPhase() = default;
  BroadPhase(const BroadPhase&) = delete;
  BroadPhase& operator=(const BroadPhase&) = delete;

  /// The detection method whose broad phase this is (`kdop`, `hash`, `sap`).
  virtual Method method() const = 0;
  /// Sets the faces to work on (once, or again to start over: drops all frame state). The
  /// topology must outlive every later call.
  virtual void build(const Topology& topology) = 0;
  /// Brings the structure to this frame: refit, rebuild, re-sort or re-hash as the method
  /// needs. Adds the method's counters and timings to `stats`.
  virtual void update(const FrameInput& in, DetectorStats& stats) = 0;
  /// Adds to `out` the candidates of the last `update`'s frame (the contract in the file
  /// comment), each once.
  virtual void self_pairs(CandidateBuffer& out, DetectorStats& stats) = 0;
  /// The bounding-volume hierarchy, for methods that keep one (else null).
  virtual const BoundingHierarchy* hierarchy() const { return nullptr; }
};

/// What `stream_self_pairs` saw: the candidate count, and whether a consumer stopped the stream.
struct StreamedPairs {
  std::size_t candidates = 0;
  bool stopped = false;
};

/// `broad.self_pairs(out, stats)` with every chunk streamed to `consumer` (`set_consumer`'s
/// chunk and resume) and none kept. `out` is left empty and not streaming, also when a call
/// throws.
inline StreamedPairs stream_self_pairs(BroadPhase& broad, CandidateBuffer& out, DetectorStats& stats,
                                       CandidateBuffer::Consumer consumer,
                                       std::size_t chunk = CandidateBuffer::kStreamChunk, bool resume = false,
                                       std::function<bool()> poll = {}) {
  out.clear();
  out.set_consumer(std::move(consumer), chunk, resume, std::move(poll));
  try {
    broad.self_pairs(out, stats);
  } catch (...) {
    out.set_consumer({});
    out.clear();
    throw;
  }
  const StreamedPairs result{out.total(), out.stopped()};
  out.set_consumer({});
  out.clear();
  return result;
}

}  // namespace crumple
