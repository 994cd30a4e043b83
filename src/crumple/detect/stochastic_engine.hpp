#pragma once
/// \file
/// The generic engine of the stochastic detector (thesis §3.2.2.6: "only the distance functions
/// between primitives are specialised"). Internal header: used by stochastic.cpp, the hybrid
/// (hybrid_detail.hpp) and their tests.
///
/// `PairEngine<Traits>` runs Algorithm 3 for one primitive pair type. A traits class supplies:
///   static constexpr PairType kType;
///   static constexpr bool kSymmetric;   // both elements of the same type: pairs stored a < b
///   static constexpr bool kSideEffect;  // walks record the colliding pairs they meet (false
///                                       // when classifying is costly, e.g. VV zone tests)
///   static Index count_a(const Topology&), count_b(const Topology&);
///   static std::span<const Index> neighbours_a(const Topology&, Index), neighbours_b(...);
///   static bool excluded(const Topology&, Index a, Index b);  // adjacent: never a contact
///   static Scalar distance(const Context&, Index a, Index b);  // the convergence metric
///   static Verdict classify(Context&, Index a, Index b, Scalar distance);  // records contacts
/// Everything else (convergence, near/duplicate deletion, random draws, propagation, caches,
/// statistics) is written once here.

#include <crumple/core/types.hpp>
#include <crumple/detect/stochastic.hpp>

#include <chrono>
#include <cstdint>
#include <limits>
#include <random>
#include <span>
#include <utility>
#include <vector>

namespace crumple::stochastic_detail {

/// Open-addressing hash map from a 64-bit pair key to a double and 32 bits of flags, cleared in
/// O(1) by bumping a generation stamp (per-frame tables must not cost O(capacity) to reset, nor
/// O(mesh size)). Multiplicative (Fibonacci) hashing, linear probing, at most half full.
class PairTable {
 public:
  /// A slot: callers read and write `flags` and `value` (both zero when inserted by `entry`).
  struct Entry {
    std::uint64_t key = 0;
    std::uint32_t gen = 0;
    std::uint32_t flags = 0;
    double value = 0;
  };

  PairTable() : slots_(64) {}

  void clear() {
    ++gen_;
    size_ = 0;
    if (gen_ == 0) {  // wrapped: invalidate every slot for real
      for (Slot& s : slots_) s.gen = 0;
      gen_ = 1;
    }
  }
  std::size_t size() const { return size_; }

  /// Pointer to the value of `key`, or null.
  const double* find(std::uint64_t key) const {
    const std::size_t mask = slots_.size() - 1;
    for (std::size_t i = index(key);; i = (i + 1) & mask) {
      const Slot& s = slots_[i];
      if (s.gen != gen_) return nullptr;
      if (s.key == key) return &s.value;
    }
  }
  bool contains(std::uint64_t key) const { return find(key) != nullptr; }

  /// Inserts `key` with `value` unless present; returns the stored value slot and whether it
  /// was inserted.
  std::pair<double*, bool> insert(std::uint64_t key, double value) {
    const auto [e, inserted] = emplace(key);
    if (inserted) e->value = value;
    return {&e->value, inserted};
  }

  /// The entry of `key`, inserted with zero flags and value when absent: one probe for a
  /// lookup and its update. The reference is valid until the next call of `entry` or `insert`.
  Entry& entry(std::uint64_t key) { return *emplace(key).first; }

 private:
  using Slot = Entry;
  std::size_t index(std::uint64_t k) const {
    return static_cast<std::size_t>((k * 0x9e3779b97f4a7c15ULL) >> shift_);
  }
  std::pair<Entry*, bool> emplace(std::uint64_t key) {
    if (2 * (size_ + 1) > slots_.size()) grow();
    const std::size_t mask = slots_.size() - 1;
    for (std::size_t i = index(key);; i = (i + 1) & mask) {
      Slot& s = slots_[i];
      if (s.gen != gen_) {
        s = {key, gen_, 0, 0};
        ++size_;
        return {&s, true};
      }
      if (s.key == key) return {&s, false};
    }
  }
  void grow() {
    std::vector<Slot> old;
    old.swap(slots_);
    slots_.assign(old.size() * 2, Slot{});
    --shift_;
    const std::uint32_t live = gen_;
    gen_ = 1;
    size_ = 0;
    for (const Slot& s : old) {
      if (s.gen == live) {
        Slot& t = *emplace(s.key).first;
        t.flags = s.flags;
        t.value = s.value;
      }
    }
  }

  std::vector<Slot> slots_;
  int shift_ = 64 - 6;  ///< 64 - log2(slots_.size())
  std::uint32_t gen_ = 1;
  std::size_t size_ = 0;
};

inline std::uint64_t pair_key(Index a, Index b) {
  return (static_cast<std::uint64_t>(static_cast<std::uint32_t>(a)) << 32) |
         static_cast<std::uint32_t>(b);
}

/// Counters of one pair type for one frame (see `StochasticDetector` for their meaning).
struct EngineStats {
  double drawn = 0, kept = 0, deleted = 0, duplicates = 0, converge_steps = 0,
         distance_evals = 0, cache_hits = 0, propagation_visits = 0, colliding = 0,
         zone_tests = 0, face_pairs = 0, kdop_rejects = 0;
  /// Kept pairs carried to the next frame without converging (time budget spent).
  double carried = 0;
  /// Walks carried to the next frame unfinished (`steps` moves made this frame).
  double walking = 0;
};

/// What a converged (or visited) pair is: colliding (contacts recorded) and/or near.
struct Verdict {
  bool colliding = false;
  bool near = false;
};

/// How one engine behaves, derived from the variant.
struct EngineConfig {
  bool direct = false;          ///< closest neighbour (all tested) instead of the first closer
  bool by_convergence = false;  ///< propagation launches convergences instead of plain tests
  bool cache = false;           ///< cache distances computed this frame
  Propagation propagation = Propagation::Linear;
  int active = 100;
  int draw = 100;
  int steps = 16;
  /// Time budget of the frame (`StochasticParams::budget_ms`): past the deadline, kept pairs
  /// are carried over unconverged, and draws and propagation stop.
  FrameDeadline deadline;  ///< none by default
};

/// Uniform integer in [0, n) from a 64-bit generator (Lemire's multiply-shift on 32 bits;
/// the bias is < n / 2^32). Same sequence on every platform.
inline Index uniform_index(std::mt19937_64& rng, Index n) {
  const std::uint64_t r = rng() >> 32;
  return static_cast<Index>((r * static_cast<std::uint64_t>(n)) >> 32);
}

/// Algorithm 3 for one pair type. `Context` is passed through to the traits.
template <class Traits, class Context>
class PairEngine {
 public:
  /// Forgets all state (new topology).
  void reset() {
    near_.clear();
    walking_.clear();
    colliding_.clear();
  }

  /// Converged near pairs kept for the next frame.
  const std::vector<PrimitivePair>& near_pairs() const { return near_; }
  /// Where the unfinished walks stand; they go on next frame.
  const std::vector<PrimitivePair>& walking_pairs() const { return walking_; }
  /// Replaces the kept pairs and walks (a restored state; the caller validates them).
  void restore(std::vector<PrimitivePair> near, std::vector<PrimitivePair> walking) {
    near_ = std::move(near);
    walking_ = std::move(walking);
    colliding_.clear();
  }
  const std::vector<PrimitivePair>& colliding_pairs() const { return colliding_; }
  const EngineStats& stats() const { return stats_; }

  // One frame is three phases — converge the kept pairs, top up with random draws, propagate —
  // that the detector runs for every pair type before the next phase, so that under a time
  // budget every type keeps its pairs before any type draws or propagates.

  /// Phase 1: resets the per-frame tables, converges the pairs kept from the last frame, then
  /// takes the unfinished walks further.
  void begin_frame(Context& ctx, const EngineConfig& config) {
    start_frame(config);
    const auto run = [&](const std::vector<PrimitivePair>& pairs, std::vector<PrimitivePair>& carry) {
      for (std::size_t i = 0; i < pairs.size(); ++i) {
        if (out_of_time()) {  // carry the rest over as they are; they go on next frame
          carry.insert(carry.end(), pairs.begin() + static_cast<std::ptrdiff_t>(i), pairs.end());
          stats_.carried += static_cast<double>(pairs.size() - i);
          return;
        }
        process(ctx, pairs[i]);
      }
    };
    run(previous_, near_);
    run(previous_walking_, walking_);
    count_kept();
  }

  /// Phase 2: random pairs while fewer than `active` are kept (at most `draw`).
  void draw(Context& ctx, std::mt19937_64& rng) {
    const Topology& topo = ctx.topo;
    const Index na = Traits::count_a(topo);
    const Index nb = Traits::count_b(topo);
    if (na > 0 && nb > 0) {
      int drawn = 0;
      while (static_cast<int>(near_.size() + walking_.size()) < config_.active && drawn < config_.draw &&
             !out_of_time()) {
        ++drawn;
        const Index a = uniform_index(rng, na);
        const Index b = uniform_index(rng, nb);
        if (Traits::excluded(topo, a, b)) continue;
        process(ctx, canon(a, b));
      }
      stats_.drawn = drawn;
    }
    count_kept();
  }

  /// Phase 3: propagation from every colliding pair (the colliding list grows while it is
  /// walked: it is the propagation queue).
  void propagate_all(Context& ctx) { propagate_from(ctx, 0); }

  // Finer steps for callers that schedule the work themselves (the hybrid detector, which runs
  // the three phases zone by zone): `start_frame`, then any sequence of `process_pair` and
  // `propagate_from`; the kept pairs of the last frame are the caller's to hand back.

  /// Resets the per-frame tables, counters and lists without processing anything; the kept
  /// pairs and walks of the last frame are forgotten (read them before).
  void start_frame(const EngineConfig& config) {
    config_ = config;
    stats_ = {};
    marks_.clear();
    colliding_.clear();
    previous_.swap(near_);
    near_.clear();
    previous_walking_.swap(walking_);
    walking_.clear();
  }
  /// Changes the configuration within a frame (per-zone parameters); the tables are kept.
  void set_config(const EngineConfig& config) { config_ = config; }
  /// Converges `p` (a kept, walking or drawn pair) and keeps it when it ends a near local
  /// minimum not reached by another walk this frame (Algorithm 3's inner step).
  void process_pair(Context& ctx, PrimitivePair p) {
    process(ctx, canon(p.a, p.b));
    count_kept();
  }
  /// Propagation from the colliding pairs recorded from index `first` on, including those it
  /// records itself; stops at the deadline. Returns the colliding count when it stopped.
  std::size_t propagate_from(Context& ctx, std::size_t first) {
    if (config_.propagation == Propagation::None) return colliding_.size();
    std::size_t i = first;
    for (; i < colliding_.size() && !out_of_time(); ++i) propagate(ctx, colliding_[i]);
    return i;
  }

 private:
  enum class Walk { Converged, Merged, Capped };
  struct WalkResult {
    PrimitivePair pair;
    Scalar distance;
    Walk status;
  };

  static PrimitivePair canon(Index a, Index b) {
    if constexpr (Traits::kSymmetric) {
      if (b < a) std::swap(a, b);
    }
    return {a, b};
  }
  static std::uint64_t key(PrimitivePair p) { return pair_key(p.a, p.b); }

  void count_kept() {
    stats_.kept = static_cast<double>(near_.size());
    stats_.walking = static_cast<double>(walking_.size());
  }

  bool out_of_time() const {
    return config_.deadline.passed();
  }

  Scalar distance(const Context& ctx, PrimitivePair p) {
    if (!config_.cache) {
      ++stats_.distance_evals;
      return Traits::distance(ctx, p.a, p.b);
    }
    PairTable::Entry& m = mark(p);
    if ((m.flags & kHasDistance) != 0) {
      ++stats_.cache_hits;
      return m.value;
    }
    ++stats_.distance_evals;
    m.value = Traits::distance(ctx, p.a, p.b);
    m.flags |= kHasDistance;
    return m.value;
  }

  /// Classifies a pair once per frame (contacts recorded by the traits); colliding pairs join
  /// the colliding list, which is also the propagation queue.
  Verdict classify(Context& ctx, PrimitivePair p, Scalar d) {
    PairTable::Entry& m = mark(p);
    if ((m.flags & kClassified) != 0) return {(m.flags & kColliding) != 0, (m.flags & kNear) != 0};
    // The traits record contacts in the sink's own tables: `m` stays valid.
    const Verdict v = Traits::classify(ctx, p.a, p.b, d);
    m.flags |= kClassified | (v.colliding ? kColliding : 0u) | (v.near ? kNear : 0u);
    if (v.colliding) {
      colliding_.push_back(p);
      ++stats_.colliding;
    }
    return v;
  }

  /// Sets `flag` on `p`; false when it was already set this frame.
  bool first_time(PrimitivePair p, std::uint32_t flag) {
    PairTable::Entry& m = mark(p);
    if ((m.flags & flag) != 0) return false;
    m.flags |= flag;
    return true;
  }

  /// Moves to `q` unless another walk reached it this frame (then this walk is a duplicate).
  bool enter(PrimitivePair q) { return first_time(q, kVisited); }

  /// Walks from p to a local minimum of the distance over the pair graph
  /// {(a', b) : a' ~ a} ∪ {(a, b') : b' ~ b} minus excluded pairs (thesis fig. 3.4).
  WalkResult converge(Context& ctx, PrimitivePair p) {
    const Topology& topo = ctx.topo;
    Scalar d = distance(ctx, p);
    // Colliding pairs a walk goes through are recorded (free: the distance is known); direct
    // convergence also records the colliding neighbours it tests (thesis §3.2.2.5).
    if (Traits::kSideEffect && d < ctx.h2) classify(ctx, p, d);
    if (!enter(p)) return {p, d, Walk::Merged};
    const bool side_effect = config_.direct && Traits::kSideEffect;
    int steps = 0;
    for (;;) {
      bool moved = false;
      if (config_.direct) {
        // The closest neighbour pair, all of them tested (colliding ones recorded).
        PrimitivePair best{-1, -1};
        Scalar best_d = d;
        const auto consider = [&](PrimitivePair q) {
          const Scalar dq = distance(ctx, q);
          if (side_effect && dq < ctx.h2) classify(ctx, q, dq);
          if (dq < best_d) {
            best_d = dq;
            best = q;
          }
        };
        for (const Index n : Traits::neighbours_a(topo, p.a)) {
          if (!Traits::excluded(topo, n, p.b)) consider(canon(n, p.b));
        }
        for (const Index n : Traits::neighbours_b(topo, p.b)) {
          if (!Traits::excluded(topo, p.a, n)) consider(canon(p.a, n));
        }
        if (best.a >= 0) {
          if (Traits::kSideEffect && best_d < ctx.h2) classify(ctx, best, best_d);
          if (!enter(best)) return {best, best_d, Walk::Merged};
          p = best;
          d = best_d;
          moved = true;
          ++steps;
          ++stats_.converge_steps;
        }
      } else {
        // The first closer neighbour pair, element 1 then element 2 (thesis fig. 3.4, 3.6).
        for (int side = 0; side < 2; ++side) {
          const auto list = side == 0 ? Traits::neighbours_a(topo, p.a) : Traits::neighbours_b(topo, p.b);
          for (const Index n : list) {
            const bool excl = side == 0 ? Traits::excluded(topo, n, p.b) : Traits::excluded(topo, p.a, n);
            if (excl) continue;
            const PrimitivePair q = side == 0 ? canon(n, p.b) : canon(p.a, n);
            const Scalar dq = distance(ctx, q);
            if (dq < d) {
              if (Traits::kSideEffect && dq < ctx.h2) classify(ctx, q, dq);
              if (!enter(q)) return {q, dq, Walk::Merged};
              p = q;
              d = dq;
              moved = true;
              ++steps;
              ++stats_.converge_steps;
              break;
            }
          }
          if (steps >= config_.steps) break;
        }
      }
      if (!moved) return {p, d, Walk::Converged};
      if (steps >= config_.steps) return {p, d, Walk::Capped};
    }
  }

  /// Converges a kept, walking or drawn pair; keeps it when it is a near local minimum not
  /// reached by another pair this frame, and carries it to the next frame when its walk is not
  /// over (so that no walk costs more than `steps` moves per frame, on any mesh size).
  void process(Context& ctx, PrimitivePair p) {
    const WalkResult r = converge(ctx, p);
    if (r.status == Walk::Merged) {
      ++stats_.deleted;
      ++stats_.duplicates;
      return;
    }
    if (r.status == Walk::Capped) {
      // Where a walk stops is no minimum: record its collision when that is free (the
      // distance is known), but do not run a costly classification (VV zone tests) on it.
      if constexpr (Traits::kSideEffect) classify(ctx, r.pair, r.distance);
      walking_.push_back(r.pair);
      return;
    }
    if (classify(ctx, r.pair, r.distance).near) {
      near_.push_back(r.pair);
    } else {
      ++stats_.deleted;
    }
  }

  /// Visits the neighbour pairs of a colliding pair (never the same pair twice in a frame).
  void propagate(Context& ctx, PrimitivePair p) {
    const Topology& topo = ctx.topo;
    const auto visit = [&](Index a, Index b) {
      if (Traits::excluded(topo, a, b)) return;
      const PrimitivePair q = canon(a, b);
      if (!first_time(q, kPropagated)) return;
      ++stats_.propagation_visits;
      if (config_.by_convergence) {
        const WalkResult r = converge(ctx, q);
        if (r.status != Walk::Merged) classify(ctx, r.pair, r.distance);
      } else {
        classify(ctx, q, distance(ctx, q));
      }
    };
    const auto na = Traits::neighbours_a(topo, p.a);
    const auto nb = Traits::neighbours_b(topo, p.b);
    for (const Index n : na) visit(n, p.b);
    for (const Index n : nb) visit(p.a, n);
    if (config_.propagation == Propagation::Full) {
      for (const Index n1 : na) {
        for (const Index n2 : nb) visit(n1, n2);
      }
    }
  }

  EngineConfig config_;
  EngineStats stats_;
  std::vector<PrimitivePair> near_, previous_, walking_, previous_walking_, colliding_;
  // What this frame knows of a pair, in one table so that a pair costs one probe however many
  // of these it has: its distance (direct and vertex variants cache it), whether a convergence
  // reached it (the "visited" set), whether propagation visited it, and its verdict.
  static constexpr std::uint32_t kHasDistance = 1, kVisited = 2, kPropagated = 4, kClassified = 8,
                                 kColliding = 16, kNear = 32;
  PairTable::Entry& mark(PrimitivePair p) { return marks_.entry(key(p)); }
  PairTable marks_;
};

}  // namespace crumple::stochastic_detail
