#pragma once
/// \file
/// Internal: the hybrid detector's state (hybrid.hpp), shared by its units: hybrid.cpp (names,
/// parameters, state, a frame's order of steps), hybrid_zones.cpp (leaves, zones and their
/// schedule, kept pairs, the risk report) and hybrid_search.cpp (the examination of each zone).

#include <crumple/detect/broad_phase/broad_phase.hpp>
#include <crumple/detect/hybrid.hpp>
#include <crumple/detect/stochastic_engine.hpp>
#include <crumple/detect/stochastic_pairs_detail.hpp>

#include <algorithm>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <random>
#include <span>
#include <tuple>
#include <vector>

namespace crumple {

namespace hybrid_detail {

using stochastic_detail::Context;
using stochastic_detail::EETraits;
using stochastic_detail::EFTraits;
using stochastic_detail::EngineConfig;
using stochastic_detail::EngineStats;
using stochastic_detail::PairEngine;
using stochastic_detail::pair_key;
using stochastic_detail::Sink;
using stochastic_detail::uniform_index;
using stochastic_detail::VFTraits;
using stochastic_detail::ZoneTester;

using Clock = std::chrono::steady_clock;

/// Pair types the hybrid runs (the vertex variant's VV type is not used).
enum Type : std::uint8_t { kEE = 0, kVF = 1, kEF = 2 };
constexpr int kTypes = 3;

/// Compressed lists: row i is data[offsets[i] .. offsets[i + 1]).
struct Rows {
  std::vector<std::size_t> offsets{0};
  std::vector<Index> data;
  std::span<const Index> operator[](Index i) const {
    const auto k = static_cast<std::size_t>(i);
    return {data.data() + offsets[k], offsets[k + 1] - offsets[k]};
  }
  void end_row() { offsets.push_back(data.size()); }
};

/// A kept pair and the zone it belongs to.
struct Kept {
  std::uint64_t zone = 0;
  std::uint8_t type = 0;
  PrimitivePair pair;
  friend bool operator<(const Kept& x, const Kept& y) {
    return std::tie(x.zone, x.type, x.pair.a, x.pair.b) < std::tie(y.zone, y.type, y.pair.a, y.pair.b);
  }
  friend bool operator==(const Kept& x, const Kept& y) {
    return x.zone == y.zone && x.type == y.type && x.pair == y.pair;
  }
};

/// A zone: what persists across frames (leaves, age, contacts) and this frame's schedule.
struct Zone {
  Index a = -1, b = -1;
  int age = 0;         ///< frames since last examined (as of this frame once `schedule` ran)
  bool never = true;   ///< never examined
  int contacts = 0;    ///< contacts found at its last examination
  // Per frame:
  int found = 0;       ///< contacts of this frame that lie in it
  bool examined = false;
  double score = 0;
  std::size_t kept_begin = 0, kept_end = 0;
  std::uint64_t key() const { return pair_key(a, b); }
};

/// Binary tree over the leaf boxes (rebuilt every frame: a few thousand leaves at most per
/// 100k faces), for the overlapping leaf pairs.
class LeafTree {
 public:
  void build(const std::vector<Box>& boxes) {
    boxes_ = &boxes;
    nodes_.clear();
    order_.resize(boxes.size());
    for (std::size_t i = 0; i < order_.size(); ++i) order_[i] = static_cast<Index>(i);
    if (!order_.empty()) build_node(0, order_.size());
  }
  /// Every overlapping pair (a <= b), the self pair of each leaf included.
  void pairs(std::vector<std::uint64_t>& out) const {
    out.clear();
    if (!nodes_.empty()) self(0, out);
  }

 private:
  struct Node {
    Box box;
    std::size_t begin = 0, end = 0;  ///< leaves order_[begin, end)
    int left = -1, right = -1;
  };
  int build_node(std::size_t begin, std::size_t end) {
    const int id = static_cast<int>(nodes_.size());
    nodes_.push_back({});
    Box box = Box::empty();
    Box centres = Box::empty();
    for (std::size_t i = begin; i < end; ++i) {
      const Box& b = (*boxes_)[static_cast<std::size_t>(order_[i])];
      box.merge(b);
      centres.grow(centre(b));
    }
    nodes_[static_cast<std::size_t>(id)].box = box;
    nodes_[static_cast<std::size_t>(id)].begin = begin;
    nodes_[static_cast<std::size_t>(id)].end = end;
    if (end - begin > 1) {
      std::size_t axis = 0;
      for (std::size_t k = 1; k < 3; ++k) {
        if (centres.hi[k] - centres.lo[k] > centres.hi[axis] - centres.lo[axis]) axis = k;
      }
      const std::size_t mid = begin + (end - begin) / 2;
      const auto first = order_.begin();
      std::nth_element(first + static_cast<std::ptrdiff_t>(begin), first + static_cast<std::ptrdiff_t>(mid),
                       first + static_cast<std::ptrdiff_t>(end), [&](Index x, Index y) {
                         const Box& bx = (*boxes_)[static_cast<std::size_t>(x)];
                         const Box& by = (*boxes_)[static_cast<std::size_t>(y)];
                         const Scalar cx = bx.lo[axis] + bx.hi[axis], cy = by.lo[axis] + by.hi[axis];
                         return cx < cy || (cx == cy && x < y);
                       });
      const int left = build_node(begin, mid);
      const int right = build_node(mid, end);
      nodes_[static_cast<std::size_t>(id)].left = left;
      nodes_[static_cast<std::size_t>(id)].right = right;
    }
    return id;
  }
  static Vec3 centre(const Box& b) {
    return {0.5 * (b.lo[0] + b.hi[0]), 0.5 * (b.lo[1] + b.hi[1]), 0.5 * (b.lo[2] + b.hi[2])};
  }
  const Node& node(int i) const { return nodes_[static_cast<std::size_t>(i)]; }
  void self(int n, std::vector<std::uint64_t>& out) const {
    const Node& x = node(n);
    if (x.left < 0) {
      const Index l = order_[x.begin];
      out.push_back(pair_key(l, l));
      return;
    }
    self(x.left, out);
    self(x.right, out);
    cross(x.left, x.right, out);
  }
  void cross(int m, int n, std::vector<std::uint64_t>& out) const {
    const Node& x = node(m);
    const Node& y = node(n);
    if (!x.box.overlaps(y.box)) return;
    const bool x_leaf = x.left < 0, y_leaf = y.left < 0;
    if (x_leaf && y_leaf) {
      const Index a = order_[x.begin], b = order_[y.begin];
      out.push_back(pair_key(std::min(a, b), std::max(a, b)));
      return;
    }
    if (y_leaf || (!x_leaf && x.end - x.begin >= y.end - y.begin)) {
      cross(x.left, n, out);
      cross(x.right, n, out);
    } else {
      cross(m, y.left, out);
      cross(m, y.right, out);
    }
  }

  const std::vector<Box>* boxes_ = nullptr;
  std::vector<Node> nodes_;
  std::vector<Index> order_;
};

inline Scalar volume(const Box& b) {
  Scalar v = 1;
  for (std::size_t k = 0; k < 3; ++k) v *= std::max<Scalar>(b.hi[k] - b.lo[k], 0);
  return v;
}

/// Whether a zone is due: never examined, or not for `every` frames.
inline bool due(const Zone& z, int every) { return z.never || z.age >= every; }

/// One frame's examination of the zones (hybrid_search.cpp): its inputs, the time budget and
/// what it counts.
struct ZoneSearchFrame {
  const Topology& topo;
  PositionsView x;
  Scalar h;
  bool run_ee, run_vf, run_ef;  ///< pair types of the query (vf, ee, tt)
  const FrameDeadline& deadline;
  Context& ctx;
  const std::vector<Kept>& old_kept;  ///< last frame's kept pairs, by zone
  std::vector<Kept> carried;          ///< kept pairs of the zones not examined (to the next frame)
  std::size_t examined = 0;
  double drawn = 0, exact_pairs = 0;
  bool out_of_time() const { return deadline.passed(); }
  /// A zone whose examination the budget cut short counts as not examined: it stays due.
  void unfinish(Zone& z) {
    z.examined = false;
    --examined;
  }
};

}  // namespace hybrid_detail

struct HybridDetector::Impl {
  using Kept = hybrid_detail::Kept;
  using Rows = hybrid_detail::Rows;
  using Zone = hybrid_detail::Zone;
  using Context = hybrid_detail::Context;
  using ZoneSearchFrame = hybrid_detail::ZoneSearchFrame;

  // Per topology.
  std::vector<Index> face_leaf, vertex_owner, edge_owner;
  Rows leaf_faces, leaf_verts, owned_verts, owned_edges;
  // Per frame.
  std::vector<Box> boxes, previous_boxes;
  std::vector<Scalar> motion, near_factor;
  std::vector<int> leaf_zones;  ///< zones each leaf is in
  std::vector<std::uint64_t> zone_keys;
  hybrid_detail::LeafTree tree;
  std::vector<Box> face_box, edge_box;
  std::vector<std::uint32_t> face_box_gen, edge_box_gen;
  std::uint32_t box_gen = 0;
  // Across frames.
  std::vector<Zone> zones;
  std::vector<ZoneInfo> infos;
  std::vector<Kept> kept;
  std::mt19937_64 rng;
  hybrid_detail::PairEngine<hybrid_detail::EETraits, Context> ee;
  hybrid_detail::PairEngine<hybrid_detail::VFTraits, Context> vf;
  hybrid_detail::PairEngine<hybrid_detail::EFTraits, Context> ef;
  hybrid_detail::Sink sink;
  hybrid_detail::ZoneTester zone_tester;  ///< unused (VV pairs only); the context needs one
  // The state before the last update (`save_state`).
  std::vector<Zone> saved_zones;
  std::vector<Kept> saved_kept;
  std::mt19937_64 saved_rng;
  bool saved = false;
  /// The cost of the last frame's work after the search (kept pairs, risk report, sort), on
  /// the budget's clock: reserved from the next frame's budget. Not state: timing only.
  StageCost post_cost;

  // ---- hybrid_zones.cpp: leaves, zones, schedule, kept pairs, risk report ----------------------
  void build(const Topology& topo, int leaf_size);
  /// Step 1: each leaf's box around its vertices (and their `previous` positions, when given),
  /// inflated by half the leaf's near distance plus its largest displacement over the last step.
  void refit_leaves(PositionsView previous, PositionsView x, Scalar h, double near);
  /// Step 2: the overlapping leaf pairs, merged with last frame's zones (age, contacts) and kept
  /// pairs. Returns last frame's kept pairs, into which each zone's `kept_begin, kept_end` point.
  std::vector<Kept> merge_zones();
  /// Step 2: the zones' priority scores; returns the zones in the order they are examined (due
  /// first, the never examined and then the oldest first; then by score).
  std::vector<std::size_t> schedule(Scalar h, bool has_previous, int every);
  /// Step 4: the kept pairs for the next frame: the engines' near pairs and walks and the
  /// `carried` pairs of the zones not examined, each filed under its zone, sorted, once each.
  void keep_pairs(const std::vector<Kept>& carried);
  /// What step 5 reports of the zones (`HybridDetector` stats).
  struct Risk {
    double est_missed = 0;
    int oldest = 0;
    std::size_t due_left = 0;
  };
  /// Step 5: the contacts of `out` per zone; ages and contacts of the examined zones reset; the
  /// zones' infos; estimated misses.
  Risk report(const ContactSet& out, int every);

  // ---- hybrid_search.cpp: the examination of the zones ---------------------------------------
  /// Step 3: examines the zones in `order` until the quota, the cap or the budget stops it.
  void examine_zones(ZoneSearchFrame& s, const std::vector<std::size_t>& order,
                     const hybrid_detail::EngineConfig& base, const HybridParams& params);
  /// `search=exact`: every pair of the zone's owned elements, behind a box pre-test.
  void search_exact(ZoneSearchFrame& s, Zone& z);
  /// `search=stochastic` (Algorithm 3 restricted to the zone): kept pairs, `n_draw` draws,
  /// propagation.
  void search_stochastic(ZoneSearchFrame& s, Zone& z, int n_draw);

  /// The zone of a pair (its owners' leaves), or ~0 when an element has no owner.
  std::uint64_t zone_of(int type, PrimitivePair p) const {
    Index la = -1, lb = -1;
    switch (type) {
      case hybrid_detail::kEE:
        la = edge_owner[static_cast<std::size_t>(p.a)], lb = edge_owner[static_cast<std::size_t>(p.b)];
        break;
      case hybrid_detail::kVF:
        la = vertex_owner[static_cast<std::size_t>(p.a)], lb = face_leaf[static_cast<std::size_t>(p.b)];
        break;
      default: la = edge_owner[static_cast<std::size_t>(p.a)], lb = face_leaf[static_cast<std::size_t>(p.b)]; break;
    }
    if (la < 0 || lb < 0) return ~std::uint64_t{0};
    return hybrid_detail::pair_key(std::min(la, lb), std::max(la, lb));
  }
  /// Index of the zone with this key, or -1.
  std::ptrdiff_t find_zone(std::uint64_t key) const {
    const auto it = std::lower_bound(zones.begin(), zones.end(), key,
                                     [](const Zone& z, std::uint64_t k) { return z.key() < k; });
    if (it == zones.end() || it->key() != key) return -1;
    return it - zones.begin();
  }
  const Box& fbox(const Topology& topo, PositionsView x, Index f) {
    const auto i = static_cast<std::size_t>(f);
    if (face_box_gen[i] != box_gen) {
      Box b = Box::empty();
      for (const Index v : topo.face(f)) b.grow(x[static_cast<std::size_t>(v)]);
      face_box[i] = b;
      face_box_gen[i] = box_gen;
    }
    return face_box[i];
  }
  const Box& ebox(const Topology& topo, PositionsView x, Index e) {
    const auto i = static_cast<std::size_t>(e);
    if (edge_box_gen[i] != box_gen) {
      Box b = Box::empty();
      for (const Index v : topo.edge(e)) b.grow(x[static_cast<std::size_t>(v)]);
      edge_box[i] = b;
      edge_box_gen[i] = box_gen;
    }
    return edge_box[i];
  }
};

}  // namespace crumple
