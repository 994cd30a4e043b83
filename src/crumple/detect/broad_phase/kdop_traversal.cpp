// The k-DOP hierarchy's self-traversal (kdop_tree_detail.hpp): the root's self-test split into
// independent tasks run in parallel; node pairs descend by float lane tests of eight members at
// once; leaf pairs emit the candidate face pairs, branch-free; coherence units reuse or record
// their candidates (kdop_cache.cpp).
#include <crumple/core/parallel.hpp>
#include <crumple/detect/broad_phase/kdop_tree_detail.hpp>

#include <algorithm>
#include <array>
#include <atomic>
#include <bit>
#include <cstdint>
#include <mutex>
#include <utility>
#include <vector>

namespace crumple::detail {

namespace {

/// Bit l set when lane l of v is 0 (the lanes of a vector comparison are 0 or -1): a sign-mask
/// instruction per half where SSE is there.
__attribute__((always_inline)) inline std::uint64_t zero_lanes(const I8& v) {
#if defined(__SSE__)
  // The halves by shuffles, in registers: a bit_cast to two F4 would go through the stack,
  // where the AVX2 clone's 32-byte store then 16-byte loads defeat store forwarding.
  const F8 f = reinterpret_cast<F8>(v);
  const F4 lo = __builtin_shufflevector(f, f, 0, 1, 2, 3);
  const F4 hi = __builtin_shufflevector(f, f, 4, 5, 6, 7);
  const auto signs = static_cast<std::uint64_t>(__builtin_ia32_movmskps(lo)) |
                     static_cast<std::uint64_t>(__builtin_ia32_movmskps(hi)) << 4;
  return ~signs & 0xFFu;
#else
  std::uint64_t m = 0;
  for (int l = 0; l < kGroup; ++l) m |= static_cast<std::uint64_t>(v[l] == 0) << l;
  return m;
#endif
}

}  // namespace

/// Slots i, j, whose float k-DOPs overlap, are a candidate face pair: they share no corner.
/// The float test is conservative (`to_float`), and the narrow phase is exact, so the double
/// k-DOPs are not tested again: that would only drop pairs within a float rounding of
/// touching, which the narrow phase rejects anyway. The tree's boxes cover the motion (the
/// hierarchy serves swept queries); contacts are proximity at the current positions, so a
/// pair whose boxes of the current positions are apart (each inflated by half the pad, like
/// the swept ones) has none and is not a candidate.
template <int K>
inline bool DopTree<K>::candidate(Index i, Index j) const {
  if (swept_ && now_apart(i, j)) return false;
  const auto si = static_cast<std::size_t>(i), sj = static_cast<std::size_t>(j);
  return !faces_share_vertex(slot_faces_[si], slot_faces_[sj]);
}

/// The current-position k-DOPs of slots i and j are apart (swept trees only).
template <int K>
inline bool DopTree<K>::now_apart(Index i, Index j) const {
  return !now_dops_[static_cast<std::size_t>(i)].overlaps(now_dops_[static_cast<std::size_t>(j)]);
}

/// The members of leaf n that, with slot i, own no sub-pair (neither owns a vertex, and not
/// both an edge): left out of a proximity query (`slot_owns_` empty otherwise).
template <int K>
inline std::uint64_t DopTree<K>::idle_with(Index n, Index i) const {
  if (slot_owns_.empty()) return 0;
  // Without a branch: which faces own what is unpredictable.
  const std::uint8_t o = slot_owns_[static_cast<std::size_t>(i)];
  const std::uint64_t owns_vertex = (o & 1u), owns_edge = (o & 2u) >> 1;
  return leaf_no_vertex_[static_cast<std::size_t>(n)] & (owns_vertex - 1) &
         (leaf_no_edge_[static_cast<std::size_t>(n)] | (owns_edge - 1));
}

/// The faces of slots i and j, the lesser first.
template <int K>
inline FacePair DopTree<K>::pair_of(Index i, Index j) const {
  const Index f = order_[static_cast<std::size_t>(i)], g = order_[static_cast<std::size_t>(j)];
  return {f < g ? f : g, f < g ? g : f};
}

/// The float k-DOP of member i (0-based) of a node, read back from its lanes.
template <int K>
__attribute__((always_inline)) inline typename DopTree<K>::FloatDop DopTree<K>::member(const Node& node,
                                                                                      Index i) const {
  const Lanes& lanes = lanes_[static_cast<std::size_t>(node.lanes + i / kGroup)];
  const int l = i % kGroup;
  FloatDop f;
  for (std::size_t j = 0; j < static_cast<std::size_t>(kAxes); ++j) {
    f.lo[j] = lanes.lo[j][l];
    f.hi[j] = lanes.hi[j][l];
  }
  return f;
}

/// Bit i set: member `first + i` of the node (child or face slot) is in `only` and may overlap
/// the k-DOP f (float, conservative; NaN never separates, as in `Kdop::overlaps`). Only the
/// lane groups with a member in `tested` (which holds `only`) are tested: a caller that
/// queries several faces against one node passes the members that any of them may want, so
/// that the groups, and the loop's count, are the same from face to face.
template <int K>
__attribute__((always_inline)) inline std::uint64_t DopTree<K>::overlapping_members(
    const Node& node, const FloatDop& f, std::uint64_t only, std::uint64_t tested) const {
  // The empty lanes past `count` overlap nothing but a NaN k-DOP: masked.
  if (node.count < 64) tested &= (std::uint64_t{1} << node.count) - 1;
  // Bit g: group g has a member in `tested`; the loop visits those only, without a
  // mispredicted test per empty group.
  std::uint64_t groups = tested | tested >> 4;
  groups |= groups >> 2;
  groups |= groups >> 1;
  groups = (groups & 0x0101010101010101u) * 0x0102040810204080u >> 56;
  std::uint64_t mask = 0;
  for (; groups != 0; groups &= groups - 1) {
    const int g = std::countr_zero(groups);
    const Lanes& lanes = lanes_[static_cast<std::size_t>(node.lanes + g)];
    I8 apart{};
    for (std::size_t j = 0; j < static_cast<std::size_t>(kAxes); ++j) {
      // Broadcasts: x - 0 is x for every x, so the subtraction folds away (x + 0 would not:
      // -0 + 0 is +0).
      const F8 lo = f.lo[j] - F8{};
      const F8 hi = f.hi[j] - F8{};
      apart |= (lanes.lo[j] > hi) | (lo > lanes.hi[j]);
    }
    mask |= zero_lanes(apart) << (kGroup * g);
  }
  return mask & only & tested;
}

/// Members of `node` that may overlap node q's k-DOP.
template <int K>
__attribute__((always_inline)) inline std::uint64_t DopTree<K>::overlapping_node(const Node& node, Index q) const {
  return overlapping_members(node, float_dops_[static_cast<std::size_t>(q)]);
}

/// Emits the pairs (slot, first + l) of `hits` for which keep(slot, first + l) holds, in one
/// flat loop without a branch per pair: a loop over each face's members in turn would end at an
/// unpredictable count for each face, and whether a pair is kept (shares no vertex) is
/// unpredictable too (pairs of adjacent leaves often share one), so every pair is written and
/// the next one goes after it or over it.
template <int K>
template <class Keep>
__attribute__((always_inline)) inline void DopTree<K>::emit_hits(Hits& hits, Index first, const Keep& keep,
                                                                 std::vector<FacePair>& out) const {
  if (hits.pairs == 0) return;
  const std::size_t base = out.size();
  out.resize(base + hits.pairs);
  std::size_t kept = base;
  for (std::size_t k = 0, p = 0; p < hits.pairs; ++p) {
    const Index i = hits.slot[k];
    const std::uint64_t m = hits.members[k];
    const Index j = first + std::countr_zero(m);
    hits.members[k] = m & (m - 1);
    k += hits.members[k] == 0 ? 1u : 0u;
    out[kept] = pair_of(i, j);
    kept += keep(i, j) ? 1u : 0u;
  }
  out.resize(kept);
}

/// Leaves a and b (node ids); only a's faces that overlap b's k-DOP are tested against b's
/// faces (adjacent leaves overlap along their shared boundary only).
template <int K>
inline void DopTree<K>::emit_leaf_pair(Index ia, Index ib, std::vector<FacePair>& out) const {
  std::uint64_t near = overlapping_node(nodes_[static_cast<std::size_t>(ia)], ib);
  if (near == 0) return;
  // b's faces that overlap a's k-DOP: only their lane groups are tested against a's faces.
  std::uint64_t near_b = overlapping_node(nodes_[static_cast<std::size_t>(ib)], ia);
  // The side whose near faces make fewer group tests against the other's near groups queries.
  const auto groups = [](std::uint64_t m) {
    m |= m >> 4;
    m |= m >> 2;
    m |= m >> 1;
    return std::popcount(m & 0x0101010101010101u);
  };
  if (std::popcount(near_b) * groups(near) < std::popcount(near) * groups(near_b)) {
    std::swap(ia, ib);
    std::swap(near, near_b);
  }
  const Node& a = nodes_[static_cast<std::size_t>(ia)];
  const Node& b = nodes_[static_cast<std::size_t>(ib)];
  Hits hits;
  for (; near != 0; near &= near - 1) {
    const Index i = a.first + std::countr_zero(near);
    hits.add(i, overlapping_members(b, member(a, i - a.first), ~idle_with(ib, i), near_b));
  }
  emit_hits(hits, b.first, [&](Index i, Index j) { return candidate(i, j); }, out);
}

/// Calls f(c, d) for each pair of children c < d of the inner node whose k-DOPs may overlap:
/// the pairs that `self` descends to (and that `traverse` splits into tasks).
template <int K>
template <class F>
__attribute__((always_inline)) inline void DopTree<K>::each_child_pair(const Node& node, const F& f) const {
  for (Index i = 0; i + 1 < node.count; ++i) {
    const Index c = node.first + i;
    for (std::uint64_t m = overlapping_node(node, c) >> (i + 1); m != 0; m &= m - 1) {
      f(c, c + 1 + std::countr_zero(m));
    }
  }
}

/// Nodes a and b, not both leaves: calls f for each pair that `pair(a, b)` descends to, the
/// larger inner node's children whose k-DOPs may overlap the other node's (and that `traverse`
/// splits into tasks).
template <int K>
template <class F>
__attribute__((always_inline)) inline void DopTree<K>::each_descent(Index a, Index b, const F& f) const {
  const Node& na = nodes_[static_cast<std::size_t>(a)];
  const Node& nb = nodes_[static_cast<std::size_t>(b)];
  if (na.leaf || (!nb.leaf && nb.faces > na.faces)) {
    for (std::uint64_t m = overlapping_node(nb, a); m != 0; m &= m - 1) f(a, nb.first + std::countr_zero(m));
  } else {
    for (std::uint64_t m = overlapping_node(na, b); m != 0; m &= m - 1) f(na.first + std::countr_zero(m), b);
  }
}

/// Self-test of node n. With kUnits, the first small node or pair of small nodes reached is a
/// coherence unit (`unit`); inside a unit, and when coherence is off, kUnits is false.
template <int K>
template <bool kUnits>
inline void DopTree<K>::self(Index n, Walk& w) const {
  if (halted(w)) return;
  if constexpr (kUnits) {
    if (small_[static_cast<std::size_t>(n)]) return unit(n, n, w);
  }
  if (culled(n)) return;
  const Node& node = nodes_[static_cast<std::size_t>(n)];
  if (node.leaf) {
    Hits hits;
    for (Index i = 0; i + 1 < node.count; ++i) {
      const Index a = node.first + i;
      // Only the members after i that are not its neighbours and own a sub-pair with it
      // (i + 1 < count <= 64).
      const std::uint64_t later = ~std::uint64_t{0} << (i + 1);
      hits.add(a, overlapping_members(node, member(node, i),
                                      ~leaf_adjacent_[static_cast<std::size_t>(a)] & ~idle_with(n, a), later));
    }
    emit_hits(hits, node.first, [&](Index a, Index b) { return !(swept_ && now_apart(a, b)); }, w.out);
    hand_over(w);
    return;
  }
  for (Index c = node.first; c < node.first + node.count; ++c) self<kUnits>(c, w);
  each_child_pair(node, [&](Index c, Index d) { pair<kUnits>(c, d, w); });
}

/// Nodes a and b, whose k-DOPs may overlap.
template <int K>
template <bool kUnits>
inline void DopTree<K>::pair(Index a, Index b, Walk& w) const {
  if (halted(w)) return;
  if constexpr (kUnits) {
    if (small_[static_cast<std::size_t>(a)] && small_[static_cast<std::size_t>(b)]) return unit(a, b, w);
  }
  const Node& na = nodes_[static_cast<std::size_t>(a)];
  const Node& nb = nodes_[static_cast<std::size_t>(b)];
  if (na.leaf && nb.leaf) {
    emit_leaf_pair(a, b, w.out);
    hand_over(w);
  } else {
    each_descent(a, b, [&](Index c, Index d) { pair<kUnits>(c, d, w); });
  }
}

/// A coherence unit: self(a) when a == b, else pair(a, b). Reuse frames: when the
/// displacements of the unit's vertices since the refresh frame differ by at most the slack,
/// the refresh frame's candidates of the unit are emitted (none when it had none); otherwise,
/// and on other frames, it is traversed, and recorded on a refresh frame.
template <int K>
inline void DopTree<K>::unit(Index a, Index b, Walk& w) const {
  const std::uint64_t key = (static_cast<std::uint64_t>(static_cast<std::uint32_t>(std::min(a, b))) << 32) |
                            static_cast<std::uint32_t>(std::max(a, b));
  if (mode_ == Mode::reuse &&
      spread(moved_[static_cast<std::size_t>(a)], moved_[static_cast<std::size_t>(b)]) <= slack_) {
    const auto it = std::lower_bound(units_.begin(), units_.end(), key,
                                     [](const Unit& u, std::uint64_t k) { return u.key < k; });
    if (it != units_.end() && it->key == key) {
      w.out.insert(w.out.end(), unit_pairs_.begin() + static_cast<std::ptrdiff_t>(it->begin),
                   unit_pairs_.begin() + static_cast<std::ptrdiff_t>(it->end));
      hand_over(w);
    }
    ++w.reused;
    return;
  }
  const bool record = mode_ == Mode::record;
  const std::size_t pairs_begin = w.pairs.size();
  if (record) w.unit_from = w.out.size();
  if (a == b) {
    self<false>(a, w);
  } else {
    pair<false>(a, b, w);
  }
  ++w.live;
  if (record) {
    w.pairs.insert(w.pairs.end(), w.out.begin() + static_cast<std::ptrdiff_t>(w.unit_from), w.out.end());
    w.unit_from = kNoUnit;
    // A unit left unfinished by a stop is not recorded (the stop also leaves the cache invalid).
    if (w.stopped) {
      w.pairs.resize(pairs_begin);
    } else if (w.pairs.size() > pairs_begin) {
      w.units.push_back({key, pairs_begin, w.pairs.size()});
    }
  }
}

/// Whether the walk is to stop: with fine streaming (`Walk::fine`), once the consumer stopped
/// the buffer, looked at in `hand_over` and by a poll every kPollVisits calls (the first call
/// included).
template <int K>
__attribute__((always_inline)) inline bool DopTree<K>::halted(Walk& w) const {
  if (w.fine == nullptr) return false;
  if (!w.stopped && w.visits++ % kPollVisits == 0 && w.fine->poll()) w.stopped = true;
  return w.stopped;
}

/// Fine streaming (`Walk::fine`): hands the walk's candidates to the consumer once there are
/// kFineChunk of them (those of a unit being recorded are copied to `pairs` first), and stops
/// the walk when the consumer has stopped the buffer.
template <int K>
inline void DopTree<K>::hand_over(Walk& w) const {
  if (w.fine == nullptr || w.out.size() < kFineChunk) return;
  if (w.unit_from != kNoUnit) {
    w.pairs.insert(w.pairs.end(), w.out.begin() + static_cast<std::ptrdiff_t>(w.unit_from), w.out.end());
    w.unit_from = 0;
  }
  w.fine->add(std::move(w.out));
  w.out = w.fine->take();
  if (w.fine->stopped()) w.stopped = true;
}

/// Splits the self-traversal of the root into independent tasks (a == b: self(a), else
/// pair(a, b) of overlapping nodes), then runs them in parallel.
template <int K>
void DopTree<K>::traverse(int threads, CandidateBuffer& out, DetectorStats& stats) {
  std::vector<std::array<Index, 2>> tasks{{0, 0}};
  const bool coherent = mode_ != Mode::off;
  // At least 64 tasks a thread, which the threads claim as they go. The splitting is serial
  // (the other threads wait meanwhile), so it stops there. The node pairs are split as the
  // recursion descends (`each_child_pair`, `each_descent`), by float lane tests, cheaper than the
  // nodes' double k-DOPs pair by pair.
  // A streamed traversal is split on one thread too, so that its chunks stay small.
  const std::size_t target = resolve_threads(threads) > 1 || out.streaming()
                                 ? 64 * static_cast<std::size_t>(resolve_threads(threads))
                                 : 1;
  for (int round = 0; round < 16 && tasks.size() < target; ++round) {
    std::vector<std::array<Index, 2>> next;
    bool expanded = false;
    for (const auto& [a, b] : tasks) {
      const Node& na = nodes_[static_cast<std::size_t>(a)];
      const Node& nb = nodes_[static_cast<std::size_t>(b)];
      // Units stay whole (their cache is keyed by the nodes).
      const bool unit = coherent && small_[static_cast<std::size_t>(a)] && small_[static_cast<std::size_t>(b)];
      if (a == b) {
        if (na.leaf || unit) {
          next.push_back({a, a});
          continue;
        }
        if (culled(a)) continue;
        expanded = true;
        for (Index c = na.first; c < na.first + na.count; ++c) next.push_back({c, c});
        each_child_pair(na, [&](Index c, Index d) { next.push_back({c, d}); });
      } else if ((na.leaf && nb.leaf) || unit) {
        next.push_back({a, b});
      } else {
        expanded = true;
        each_descent(a, b, [&](Index c, Index d) { next.push_back({c, d}); });
      }
    }
    tasks = std::move(next);
    if (!expanded) break;
  }
  stats.set("tasks", static_cast<double>(tasks.size()));
  std::mutex mutex;
  std::size_t reused = 0, live = 0;
  std::atomic<bool> cut{false};  // a consumer stopped the traversal: some tasks were skipped
  // Resuming, the tasks are taken from the one the last stopped traversal left out, around.
  const std::size_t first = out.resuming() && resume_ < tasks.size() ? resume_ : 0;
  std::atomic<std::size_t> left_out{tasks.size()};  // the first task in that order left out
  std::vector<std::vector<Unit>> units;  // record frames: per chunk, into pairs[chunk]
  std::vector<std::vector<FacePair>> pairs;
  parallel_for_chunks(tasks.size(), threads, 1, [&](std::size_t begin, std::size_t end) {
    Walk w;
    w.out = out.take();
    if (out.streaming() && out.stream_chunk() < kFineChunk) w.fine = &out;
    const auto left = [&](std::size_t i) {  // task i (in this frame's order) was not finished
      cut.store(true, std::memory_order_relaxed);
      std::size_t seen = left_out.load();
      while (i < seen && !left_out.compare_exchange_weak(seen, i)) {
      }
    };
    for (std::size_t i = begin; i < end; ++i) {
      if (out.stopped()) {
        left(i);
        break;
      }
      const auto [a, b] = tasks[(i + first) % tasks.size()];
      if (a == b) {
        coherent ? self<true>(a, w) : self<false>(a, w);
      } else {
        coherent ? pair<true>(a, b, w) : pair<false>(a, b, w);
      }
      if (w.stopped) {  // stopped inside the task: a resumed frame begins with it again
        left(i);
        break;
      }
      // Streaming only. A unit lies in one task, and a recording copies its pairs (w.pairs).
      out.flush_if_full(w.out);
    }
    out.add(std::move(w.out));
    const std::lock_guard lock(mutex);
    reused += w.reused;
    live += w.live;
    if (!w.units.empty()) {
      units.push_back(std::move(w.units));
      pairs.push_back(std::move(w.pairs));
    }
  });
  resume_ = cut.load() && left_out.load() < tasks.size() ? (left_out.load() + first) % tasks.size() : 0;
  if (mode_ == Mode::record) {
    for (std::size_t c = 0; c < units.size(); ++c) {
      for (Unit u : units[c]) {
        u.begin += unit_pairs_.size();
        u.end += unit_pairs_.size();
        units_.push_back(u);
      }
      unit_pairs_.insert(unit_pairs_.end(), pairs[c].begin(), pairs[c].end());
    }
    std::sort(units_.begin(), units_.end(), [](const Unit& x, const Unit& y) { return x.key < y.key; });
    // A unit left out by a stop is not recorded, and a reuse frame would emit nothing for it.
    cache_valid_ = !cut.load();
  }
  if (coherent) {
    stats.set("units_reused", static_cast<double>(reused));
    stats.set("units_traversed", static_cast<double>(live));
  }
}

#define CRUMPLE_KDOP_INSTANTIATE(K) template void DopTree<K>::traverse(int, CandidateBuffer&, DetectorStats&);
CRUMPLE_KDOP_FOR_EACH_K(CRUMPLE_KDOP_INSTANTIATE)
#undef CRUMPLE_KDOP_INSTANTIATE

}  // namespace crumple::detail
