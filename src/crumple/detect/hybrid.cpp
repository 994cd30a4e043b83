#include <crumple/core/error.hpp>
#include <crumple/core/json.hpp>
#include <crumple/detect/broad_phase/broad_phase.hpp>
#include <crumple/detect/hybrid.hpp>
#include <crumple/detect/stochastic_engine.hpp>
#include <crumple/detect/stochastic_pairs_detail.hpp>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <sstream>
#include <string>
#include <tuple>

namespace crumple {

// ---------------------------------------------------------------------------------------------
// Names and parameters

std::string_view to_string(ZoneSearch search) {
  switch (search) {
    case ZoneSearch::Stochastic: return "stochastic";
    case ZoneSearch::Exact: return "exact";
  }
  return "?";
}

HybridParams HybridParams::from_spec(const MethodSpec& spec) {
  const auto fail = [&](const std::string& message) {
    throw InputError("method " + spec.to_string() + ": " + message);
  };
  HybridParams p;
  const long long leaf = spec.get_int("leaf", 64);
  if (leaf < 4 || leaf > 4096) fail("leaf must be in [4, 4096], got " + std::to_string(leaf));
  p.leaf = static_cast<int>(leaf);
  const long long every = spec.get_int("every", 1);
  if (every < 1 || every > 1'000'000) fail("every must be in [1, 1e6], got " + std::to_string(every));
  p.every = static_cast<int>(every);
  p.budget_ms = spec.get_double("budget", 0);
  if (!(p.budget_ms >= 0 && p.budget_ms <= 1e6)) fail("budget must be in [0, 1e6] ms (0 = none)");
  const long long zones = spec.get_int("zones", 0);
  if (zones < 0 || zones > 100'000'000) fail("zones must be in [0, 1e8] (0 = all), got " + std::to_string(zones));
  p.zones = static_cast<int>(zones);
  static constexpr std::array<std::string_view, 2> kSearch{"stochastic", "exact"};
  p.search = spec.get_choice("search", "stochastic", kSearch) == "exact" ? ZoneSearch::Exact : ZoneSearch::Stochastic;
  const long long draw = spec.get_int("draw", 0);
  if (draw < 0 || draw > 100'000'000) fail("draw must be in [0, 1e8] (0 = adaptive), got " + std::to_string(draw));
  p.draw = static_cast<int>(draw);
  static constexpr std::array<std::string_view, 4> kPropagation{"auto", "none", "linear", "full"};
  const std::string prop = spec.get_choice("propagation", "linear", kPropagation);
  p.auto_propagation = prop == "auto";
  if (prop == "none") p.propagation = Propagation::None;
  if (prop == "full") p.propagation = Propagation::Full;
  p.near = spec.get_double("near", 0);
  if (!(std::isfinite(p.near) && (p.near == 0 || p.near >= 1))) {
    fail("near must be 0 (adaptive) or a finite multiple >= 1 of the thickness");
  }
  const long long steps = spec.get_int("steps", 8);
  if (steps < 1 || steps > 100'000'000) fail("steps must be in [1, 1e8], got " + std::to_string(steps));
  p.steps = static_cast<int>(steps);
  const long long seed = spec.get_int("seed", 1);
  if (seed < 0) fail("seed must be >= 0");
  p.seed = static_cast<std::uint64_t>(seed);
  return p;
}

std::string HybridParams::to_string() const {
  char near_text[32];
  std::snprintf(near_text, sizeof near_text, "%g", near);
  return "hybrid:leaf=" + std::to_string(leaf) + ",every=" + std::to_string(every) +
         ",budget=" + json_number(budget_ms) + ",zones=" + std::to_string(zones) +
         ",search=" + std::string(crumple::to_string(search)) + ",draw=" + std::to_string(draw) +
         ",propagation=" + (auto_propagation ? std::string("auto") : std::string(crumple::to_string(propagation))) +
         ",near=" + near_text + ",steps=" + std::to_string(steps) + ",seed=" + std::to_string(seed);
}

// ---------------------------------------------------------------------------------------------
// The detector

namespace {

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

Scalar volume(const Box& b) {
  Scalar v = 1;
  for (std::size_t k = 0; k < 3; ++k) v *= std::max<Scalar>(b.hi[k] - b.lo[k], 0);
  return v;
}

}  // namespace

struct HybridDetector::Impl {
  // Per topology.
  std::vector<Index> face_leaf, vertex_owner, edge_owner;
  Rows leaf_faces, leaf_verts, owned_verts, owned_edges;
  // Per frame.
  std::vector<Box> boxes, previous_boxes;
  std::vector<Scalar> motion, near_factor;
  std::vector<int> leaf_zones;  ///< zones each leaf is in
  std::vector<std::uint64_t> zone_keys;
  LeafTree tree;
  std::vector<Box> face_box, edge_box;
  std::vector<std::uint32_t> face_box_gen, edge_box_gen;
  std::uint32_t box_gen = 0;
  // Across frames.
  std::vector<Zone> zones;
  std::vector<ZoneInfo> infos;
  std::vector<Kept> kept;
  std::mt19937_64 rng;
  PairEngine<EETraits, Context> ee;
  PairEngine<VFTraits, Context> vf;
  PairEngine<EFTraits, Context> ef;
  Sink sink;
  ZoneTester zone_tester;  ///< unused (VV pairs only); the context needs one
  // The state before the last update (`save_state`).
  std::vector<Zone> saved_zones;
  std::vector<Kept> saved_kept;
  std::mt19937_64 saved_rng;
  bool saved = false;

  void build(const Topology& topo, int leaf_size);
  /// The zone of a pair (its owners' leaves), or ~0 when an element has no owner.
  std::uint64_t zone_of(int type, PrimitivePair p) const {
    Index la = -1, lb = -1;
    switch (type) {
      case kEE: la = edge_owner[static_cast<std::size_t>(p.a)], lb = edge_owner[static_cast<std::size_t>(p.b)]; break;
      case kVF: la = vertex_owner[static_cast<std::size_t>(p.a)], lb = face_leaf[static_cast<std::size_t>(p.b)]; break;
      default: la = edge_owner[static_cast<std::size_t>(p.a)], lb = face_leaf[static_cast<std::size_t>(p.b)]; break;
    }
    if (la < 0 || lb < 0) return ~std::uint64_t{0};
    return pair_key(std::min(la, lb), std::max(la, lb));
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

void HybridDetector::Impl::build(const Topology& topo, int leaf_size) {
  const Index nf = topo.num_faces();
  face_leaf.assign(static_cast<std::size_t>(nf), -1);
  leaf_faces = {};
  // Patches grown breadth-first over edge-adjacent faces, seeded next to the last patch (so
  // patches tile the surface compactly), else at the lowest unassigned face.
  std::vector<Index> queue, frontier;
  Index next_seed = 0;
  Index leaf = 0;
  while (true) {
    Index seed = -1;
    while (!frontier.empty() && seed < 0) {
      const Index f = frontier.back();
      frontier.pop_back();
      if (face_leaf[static_cast<std::size_t>(f)] < 0) seed = f;
    }
    if (seed < 0) {
      while (next_seed < nf && face_leaf[static_cast<std::size_t>(next_seed)] >= 0) ++next_seed;
      if (next_seed == nf) break;
      seed = next_seed;
    }
    queue.assign(1, seed);
    face_leaf[static_cast<std::size_t>(seed)] = leaf;
    std::size_t head = 0;
    int count = 1;
    std::vector<Index> left_over;
    while (head < queue.size()) {
      const Index f = queue[head++];
      leaf_faces.data.push_back(f);
      for (const Index e : topo.face_edges(f)) {
        for (const Index g : topo.edge_faces()[e]) {
          if (face_leaf[static_cast<std::size_t>(g)] >= 0) continue;
          if (count < leaf_size) {
            face_leaf[static_cast<std::size_t>(g)] = leaf;
            queue.push_back(g);
            ++count;
          } else {
            left_over.push_back(g);
          }
        }
      }
    }
    leaf_faces.end_row();
    // Seeds for the next patches: the faces this one could not take, nearest last.
    frontier.insert(frontier.end(), left_over.rbegin(), left_over.rend());
    ++leaf;
  }
  const Index nl = leaf;
  vertex_owner.assign(static_cast<std::size_t>(topo.num_vertices()), -1);
  for (Index v = 0; v < topo.num_vertices(); ++v) {
    const auto faces = topo.vertex_faces()[v];
    if (!faces.empty()) vertex_owner[static_cast<std::size_t>(v)] = face_leaf[static_cast<std::size_t>(faces[0])];
  }
  edge_owner.assign(static_cast<std::size_t>(topo.num_edges()), -1);
  for (Index e = 0; e < topo.num_edges(); ++e) {
    const auto faces = topo.edge_faces()[e];
    if (!faces.empty()) edge_owner[static_cast<std::size_t>(e)] = face_leaf[static_cast<std::size_t>(faces[0])];
  }
  leaf_verts = {};
  owned_verts = {};
  owned_edges = {};
  std::vector<Index> mark(static_cast<std::size_t>(topo.num_vertices()), -1);
  std::vector<Index> emark(static_cast<std::size_t>(topo.num_edges()), -1);
  for (Index l = 0; l < nl; ++l) {
    for (const Index f : leaf_faces[l]) {
      for (const Index v : topo.face(f)) {
        if (mark[static_cast<std::size_t>(v)] == l) continue;
        mark[static_cast<std::size_t>(v)] = l;
        leaf_verts.data.push_back(v);
        if (vertex_owner[static_cast<std::size_t>(v)] == l) owned_verts.data.push_back(v);
      }
      for (const Index e : topo.face_edges(f)) {
        if (emark[static_cast<std::size_t>(e)] == l) continue;
        emark[static_cast<std::size_t>(e)] = l;
        if (edge_owner[static_cast<std::size_t>(e)] == l) owned_edges.data.push_back(e);
      }
    }
    leaf_verts.end_row();
    owned_verts.end_row();
    owned_edges.end_row();
  }
  boxes.assign(static_cast<std::size_t>(nl), Box::empty());
  previous_boxes = boxes;
  motion.assign(static_cast<std::size_t>(nl), 0);
  near_factor.assign(static_cast<std::size_t>(nl), 2);
  leaf_zones.assign(static_cast<std::size_t>(nl), 0);
  face_box.assign(static_cast<std::size_t>(nf), Box::empty());
  face_box_gen.assign(static_cast<std::size_t>(nf), 0);
  edge_box.assign(static_cast<std::size_t>(topo.num_edges()), Box::empty());
  edge_box_gen.assign(static_cast<std::size_t>(topo.num_edges()), 0);
  box_gen = 0;
}

HybridDetector::HybridDetector(DetectorOptions options, HybridParams params)
    : Detector(options), params_(params), impl_(std::make_unique<Impl>()) {
  if (params_.leaf < 4 || params_.every < 1 || params_.zones < 0 || params_.draw < 0 || params_.steps < 1 ||
      !(params_.budget_ms >= 0) || !(std::isfinite(params_.near) && (params_.near == 0 || params_.near >= 1))) {
    throw InputError("hybrid: invalid parameters " + params_.to_string() +
                     " (leaf >= 4, every >= 1, zones >= 0, draw >= 0, steps >= 1, budget >= 0, near 0 or >= 1)");
  }
}

HybridDetector::~HybridDetector() = default;

Index HybridDetector::num_leaves() const { return static_cast<Index>(impl_->leaf_faces.offsets.size() - 1); }

std::span<const Index> HybridDetector::leaf_faces(Index leaf) const {
  CRUMPLE_CHECK(leaf >= 0 && leaf < num_leaves(), "leaf_faces: leaf out of range");
  return impl_->leaf_faces[leaf];
}

std::span<const ZoneInfo> HybridDetector::zones() const { return impl_->infos; }

void HybridDetector::on_topology() {
  Impl& m = *impl_;
  m.build(topology(), params_.leaf);
  m.zones.clear();
  m.infos.clear();
  m.kept.clear();
  m.ee.reset();
  m.vf.reset();
  m.ef.reset();
  m.zone_tester.reset(0);
  m.rng.seed(params_.seed);
  m.saved = false;
}

std::string HybridDetector::save_state() const {
  const Impl& m = *impl_;
  const std::vector<Zone>& zones = m.saved ? m.saved_zones : m.zones;
  const std::vector<Kept>& kept = m.saved ? m.saved_kept : m.kept;
  std::ostringstream out;
  out << "hybrid-state-1 " << params_.to_string() << " rng " << (m.saved ? m.saved_rng : m.rng) << " zones "
      << zones.size();
  for (const Zone& z : zones) {
    out << " " << z.a << " " << z.b << " " << z.age << " " << (z.never ? 1 : 0) << " " << z.contacts;
  }
  out << " kept " << kept.size();
  for (const Kept& k : kept) out << " " << int(k.type) << " " << k.pair.a << " " << k.pair.b;
  return out.str();
}

void HybridDetector::load_state(std::string_view text) {
  if (text.find_first_not_of(" \t\r\n") == std::string_view::npos) return;
  const Topology& topo = topology();
  Impl& m = *impl_;
  std::istringstream in{std::string(text)};
  const auto fail = [](const std::string& what) { throw InputError("hybrid detector state: " + what); };
  std::string word, params;
  in >> word >> params;
  if (word != "hybrid-state-1") fail("expected 'hybrid-state-1', got '" + word + "'");
  if (params != params_.to_string()) fail("saved with " + params + " but the detector is " + params_.to_string());
  if (!(in >> word) || word != "rng") fail("expected 'rng'");
  std::mt19937_64 rng;
  if (!(in >> rng)) fail("bad generator state");
  if (!(in >> word) || word != "zones") fail("expected 'zones'");
  std::size_t n = 0;
  if (!(in >> n)) fail("expected a zone count");
  const auto leaves = static_cast<std::size_t>(num_leaves());
  if (n > leaves * (leaves + 1) / 2) fail("more zones than leaf pairs");
  std::vector<Zone> zones(n);
  for (Zone& z : zones) {
    int never = 0;
    if (!(in >> z.a >> z.b >> z.age >> never >> z.contacts)) fail("truncated zone list");
    if (z.a < 0 || z.b < z.a || z.b >= num_leaves()) fail("zone leaves out of range for this mesh");
    if (z.age < 0 || (never != 0 && never != 1) || z.contacts < 0) fail("bad zone age, flag or contact count");
    z.never = never == 1;
  }
  for (std::size_t i = 1; i < zones.size(); ++i) {
    if (!(zones[i - 1].key() < zones[i].key())) fail("zones not in order");
  }
  if (!(in >> word) || word != "kept") fail("expected 'kept'");
  if (!(in >> n)) fail("expected a kept pair count");
  std::vector<Kept> kept;
  for (std::size_t i = 0; i < n; ++i) {
    int type = 0;
    Kept k;
    if (!(in >> type >> k.pair.a >> k.pair.b)) fail("truncated kept pair list");
    if (type < 0 || type >= kTypes) fail("bad pair type");
    const Index na = type == kVF ? topo.num_vertices() : topo.num_edges();
    const Index nb = type == kEE ? topo.num_edges() : topo.num_faces();
    if (k.pair.a < 0 || k.pair.a >= na || k.pair.b < 0 || k.pair.b >= nb) fail("pair out of range for this mesh");
    k.type = static_cast<std::uint8_t>(type);
    k.zone = m.zone_of(type, k.pair);
    kept.push_back(k);
  }
  if (in >> word) fail("unexpected '" + word + "' after the kept pairs");
  std::sort(kept.begin(), kept.end());
  m.rng = rng;
  m.zones = std::move(zones);
  m.kept = std::move(kept);
  m.saved = false;
}

void HybridDetector::detect(PositionsView previous, PositionsView x, ContactSet& out) {
  out.clear();
  const auto start = Clock::now();
  const Topology& topo = topology();
  Impl& m = *impl_;
  const Scalar h = options().thickness;
  const ContactKinds& kinds = options().kinds;
  const bool has_previous = !previous.empty();
  const bool budget = params_.budget_ms > 0;
  const auto deadline =
      start + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double, std::milli>(params_.budget_ms));
  const auto out_of_time = [&] { return budget && Clock::now() >= deadline; };
  const auto ms_since = [](Clock::time_point t) {
    return std::chrono::duration<double, std::milli>(Clock::now() - t).count();
  };

  m.saved_zones = m.zones;
  m.saved_kept = m.kept;
  m.saved_rng = m.rng;
  m.saved = true;

  // 1. Refit the leaves: boxes around the current (and previous) positions, inflated by half
  //    the leaf's near distance plus its largest displacement over the last step.
  const Index nl = num_leaves();
  for (Index l = 0; l < nl; ++l) {
    Box b = Box::empty(), pb = Box::empty();
    Scalar move2 = 0;
    for (const Index v : m.leaf_verts[l]) {
      const Vec3& p = x[static_cast<std::size_t>(v)];
      b.grow(p);
      if (has_previous) {
        const Vec3& q = previous[static_cast<std::size_t>(v)];
        pb.grow(q);
        move2 = std::max(move2, (p - q).squaredNorm());
      }
    }
    const auto i = static_cast<std::size_t>(l);
    const Scalar move = std::sqrt(move2);
    m.motion[i] = move;
    m.near_factor[i] = params_.near > 0 ? params_.near
                                        : std::clamp<Scalar>(h > 0 ? 1 + 2 * move / h : 2, 2, 8);
    m.previous_boxes[i] = has_previous ? pb : b;
    if (has_previous) b.merge(pb);
    b.inflate(0.5 * m.near_factor[i] * h + move);
    m.boxes[i] = b;
  }
  if (++m.box_gen == 0) {
    std::fill(m.face_box_gen.begin(), m.face_box_gen.end(), 0);
    std::fill(m.edge_box_gen.begin(), m.edge_box_gen.end(), 0);
    m.box_gen = 1;
  }
  const double refit_ms = ms_since(start);

  // 2. Zones: overlapping leaf pairs, merged with last frame's (age, contacts) and kept pairs.
  const auto zones_start = Clock::now();
  m.tree.build(m.boxes);
  m.tree.pairs(m.zone_keys);
  std::sort(m.zone_keys.begin(), m.zone_keys.end());
  std::vector<Zone> zones;
  zones.reserve(m.zone_keys.size());
  {
    std::size_t j = 0, k = 0;
    for (const std::uint64_t key : m.zone_keys) {
      Zone z;
      z.a = static_cast<Index>(key >> 32);
      z.b = static_cast<Index>(key & 0xffffffffu);
      while (j < m.zones.size() && m.zones[j].key() < key) ++j;
      if (j < m.zones.size() && m.zones[j].key() == key) {
        z.age = m.zones[j].age + 1;
        z.never = m.zones[j].never;
        z.contacts = m.zones[j].contacts;
      } else {
        z.age = 1;
      }
      while (k < m.kept.size() && m.kept[k].zone < key) ++k;  // pairs of vanished zones are dropped
      z.kept_begin = k;
      while (k < m.kept.size() && m.kept[k].zone == key) ++k;
      z.kept_end = k;
      zones.push_back(z);
    }
  }
  m.zones.swap(zones);
  std::fill(m.leaf_zones.begin(), m.leaf_zones.end(), 0);
  for (const Zone& z : m.zones) {
    ++m.leaf_zones[static_cast<std::size_t>(z.a)];
    if (z.a != z.b) ++m.leaf_zones[static_cast<std::size_t>(z.b)];
  }
  std::vector<Kept> old_kept;
  old_kept.swap(m.kept);

  // Priority: contacts at the last examination first, then closeness and approach speed.
  for (Zone& z : m.zones) {
    const Box& A = m.boxes[static_cast<std::size_t>(z.a)];
    const Box& B = m.boxes[static_cast<std::size_t>(z.b)];
    double closeness = 0, approach = 0;
    if (z.a == z.b) {  // a folded patch: its box is thick for its size
      const Scalar r = 0.5 * m.near_factor[static_cast<std::size_t>(z.a)] * h + m.motion[static_cast<std::size_t>(z.a)];
      Scalar lo = std::numeric_limits<Scalar>::infinity(), hi = 0;
      for (std::size_t k = 0; k < 3; ++k) {
        lo = std::min(lo, A.hi[k] - A.lo[k] - 2 * r);
        hi = std::max(hi, A.hi[k] - A.lo[k]);
      }
      closeness = hi > 0 ? std::clamp<double>(lo / hi, 0, 1) : 0;
    } else {
      Box inter = A;
      for (std::size_t k = 0; k < 3; ++k) {
        inter.lo[k] = std::max(A.lo[k], B.lo[k]);
        inter.hi[k] = std::min(A.hi[k], B.hi[k]);
      }
      const Scalar small = std::min(volume(A), volume(B));
      closeness = small > 0 ? std::clamp<double>(volume(inter) / small, 0, 1) : 1;
      if (has_previous && h > 0) {
        const Box& pA = m.previous_boxes[static_cast<std::size_t>(z.a)];
        const Box& pB = m.previous_boxes[static_cast<std::size_t>(z.b)];
        Vec3 d, rel;
        for (int k = 0; k < 3; ++k) {
          const auto u = static_cast<std::size_t>(k);
          d[k] = 0.5 * ((B.lo[u] + B.hi[u]) - (A.lo[u] + A.hi[u]));
          rel[k] = 0.5 * ((B.lo[u] + B.hi[u]) - (pB.lo[u] + pB.hi[u]) - (A.lo[u] + A.hi[u]) + (pA.lo[u] + pA.hi[u]));
        }
        const Scalar len = d.norm();
        if (len > 0) approach = std::clamp<double>(-d.dot(rel) / len / h, 0, 4);
      }
    }
    z.score = 10.0 * z.contacts + 4 * closeness + approach;
  }
  std::vector<std::size_t> order(m.zones.size());
  for (std::size_t i = 0; i < order.size(); ++i) order[i] = i;
  const int every = params_.every;
  const auto due = [&](const Zone& z) { return z.never || z.age >= every; };
  std::stable_sort(order.begin(), order.end(), [&](std::size_t i, std::size_t j) {
    const Zone& a = m.zones[i];
    const Zone& b = m.zones[j];
    const bool da = due(a), db = due(b);
    if (da != db) return da;
    if (da) {
      if (a.never != b.never) return a.never;
      if (a.age != b.age) return a.age > b.age;
    }
    return a.score > b.score;
  });
  const double zones_ms = ms_since(zones_start);

  // 3. Examine the zones in order.
  const auto search_start = Clock::now();
  m.sink.begin(topo, x, h * h, kinds, out);
  EngineStats zone_stats;
  Context ctx{topo, x, h * h, 2 * h, 4 * h * h, m.sink, m.zone_tester, zone_stats};
  EngineConfig base;
  base.direct = true;
  base.by_convergence = true;
  base.cache = true;
  base.steps = params_.steps;
  base.has_deadline = budget;
  base.deadline = deadline;
  m.ee.start_frame(base);
  m.vf.start_frame(base);
  m.ef.start_frame(base);
  const bool run_ee = kinds.ee, run_vf = kinds.vf, run_ef = kinds.tt;
  const std::size_t quota = (m.zones.size() + static_cast<std::size_t>(every) - 1) / static_cast<std::size_t>(every);
  const std::size_t cap = params_.zones > 0 ? static_cast<std::size_t>(params_.zones) : m.zones.size();
  std::size_t examined = 0, zones_due = 0;
  double drawn = 0, exact_pairs = 0;
  for (const Zone& z : m.zones) zones_due += due(z) ? 1 : 0;
  const auto rows_size = [](std::span<const Index> s) { return static_cast<Index>(s.size()); };
  std::vector<Kept> carried;
  // A zone whose examination the budget cut short counts as not examined: it stays due.
  const auto unfinish = [&](Zone& z) {
    z.examined = false;
    --examined;
  };

  for (const std::size_t zi : order) {
    Zone& z = m.zones[zi];
    const bool wanted = every == 1 || due(z) || z.contacts > 0 || examined < quota;
    if (!wanted || examined >= cap || out_of_time()) {
      carried.insert(carried.end(), old_kept.begin() + static_cast<std::ptrdiff_t>(z.kept_begin),
                     old_kept.begin() + static_cast<std::ptrdiff_t>(z.kept_end));
      continue;
    }
    ++examined;
    z.examined = true;
    const auto la = static_cast<std::size_t>(z.a), lb = static_cast<std::size_t>(z.b);
    const Scalar nz = 0.5 * (m.near_factor[la] + m.near_factor[lb]) * h;
    ctx.near = nz;
    ctx.near2 = nz * nz;
    const Index particles = rows_size(m.owned_verts[z.a]) + (z.a == z.b ? 0 : rows_size(m.owned_verts[z.b]));
    const double share = particles > 0 ? static_cast<double>(z.contacts) / particles : 0;
    // A leaf's particles are shared among the zones it is in, so that the draws of a frame
    // follow the rule over the whole mesh, not once per zone.
    const double zone_particles =
        static_cast<double>(rows_size(m.owned_verts[z.a])) / m.leaf_zones[la] +
        (z.a == z.b ? 0.0 : static_cast<double>(rows_size(m.owned_verts[z.b])) / m.leaf_zones[lb]);
    EngineConfig config = base;
    config.propagation = params_.auto_propagation ? (share > 0.5 ? Propagation::None : Propagation::Linear)
                                                  : params_.propagation;
    m.ee.set_config(config);
    m.vf.set_config(config);
    m.ef.set_config(config);

    if (params_.search == ZoneSearch::Exact) {
      // Every pair of owned elements, behind a box pre-test (the box of one side grown by h).
      const auto vf_side = [&](Index owner, Index other) {
        for (const Index v : m.owned_verts[owner]) {
          if (out_of_time()) return;
          const Vec3& p = x[static_cast<std::size_t>(v)];
          for (const Index f : m.leaf_faces[other]) {
            Box b = m.fbox(topo, x, f);
            b.inflate(h);
            if (!b.contains(p) || topo.face_has_vertex(f, v)) continue;
            ++exact_pairs;
            m.sink.add_vf(v, f);
          }
        }
      };
      if (run_vf) {
        vf_side(z.a, z.b);
        if (z.a != z.b) vf_side(z.b, z.a);
      }
      if (run_ee) {
        const auto ea = m.owned_edges[z.a];
        const auto eb = m.owned_edges[z.b];
        for (std::size_t i = 0; i < ea.size() && !out_of_time(); ++i) {
          Box b = m.ebox(topo, x, ea[i]);
          b.inflate(h);
          for (std::size_t j = z.a == z.b ? i + 1 : 0; j < eb.size(); ++j) {
            if (!b.overlaps(m.ebox(topo, x, eb[j])) || topo.edges_adjacent(ea[i], eb[j])) continue;
            ++exact_pairs;
            m.sink.add_ee(ea[i], eb[j]);
          }
        }
      }
      if (run_ef) {
        const auto fa = m.leaf_faces[z.a];
        const auto fb = m.leaf_faces[z.b];
        for (std::size_t i = 0; i < fa.size() && !out_of_time(); ++i) {
          const Box& b = m.fbox(topo, x, fa[i]);
          for (std::size_t j = z.a == z.b ? i + 1 : 0; j < fb.size(); ++j) {
            if (!b.overlaps(m.fbox(topo, x, fb[j])) || topo.faces_adjacent(fa[i], fb[j])) continue;
            ++exact_pairs;
            m.sink.add_tt(fa[i], fb[j]);
          }
        }
      }
      if (out_of_time()) unfinish(z);
      continue;
    }

    // The stochastic search (Algorithm 3 restricted to the zone): kept pairs, draws, propagation.
    const std::size_t c_ee = m.ee.colliding_pairs().size();
    const std::size_t c_vf = m.vf.colliding_pairs().size();
    const std::size_t c_ef = m.ef.colliding_pairs().size();
    for (std::size_t k = z.kept_begin; k < z.kept_end; ++k) {
      if (out_of_time()) {  // the rest wait, as they are, for the next frame
        carried.insert(carried.end(), old_kept.begin() + static_cast<std::ptrdiff_t>(k),
                       old_kept.begin() + static_cast<std::ptrdiff_t>(z.kept_end));
        break;
      }
      const Kept& kp = old_kept[k];
      if (kp.type == kEE && run_ee) m.ee.process_pair(ctx, kp.pair);
      if (kp.type == kVF && run_vf) m.vf.process_pair(ctx, kp.pair);
      if (kp.type == kEF && run_ef) m.ef.process_pair(ctx, kp.pair);
    }
    // Draws: the thesis' rule of thumb per zone (10% of its particles below 30% in collision,
    // one per particle above 50%, linear between), or a fixed count.
    int n_draw = params_.draw;
    if (n_draw == 0) {
      const double rate = share < 0.3 ? 0.1 : share > 0.5 ? 1.0 : 0.1 + (share - 0.3) / 0.2 * 0.9;
      n_draw = std::max(1, static_cast<int>(std::ceil(rate * zone_particles)));
    }
    const auto pick = [&](std::span<const Index> s) {
      return s[static_cast<std::size_t>(uniform_index(m.rng, static_cast<Index>(s.size())))];
    };
    for (int d = 0; d < n_draw && !out_of_time(); ++d) {
      const bool swap = z.a != z.b && (m.rng() & 1) != 0;
      const Index p = swap ? z.b : z.a, q = swap ? z.a : z.b;
      if (run_ee && !m.owned_edges[p].empty() && !m.owned_edges[q].empty()) {
        const Index e0 = pick(m.owned_edges[p]), e1 = pick(m.owned_edges[q]);
        ++drawn;
        if (!EETraits::excluded(topo, e0, e1)) m.ee.process_pair(ctx, {e0, e1});
      }
      if (run_vf && !m.owned_verts[p].empty()) {
        const Index v = pick(m.owned_verts[p]), f = pick(m.leaf_faces[q]);
        ++drawn;
        if (!VFTraits::excluded(topo, v, f)) m.vf.process_pair(ctx, {v, f});
      }
      if (run_ef && !m.owned_edges[p].empty()) {
        const Index e = pick(m.owned_edges[p]), f = pick(m.leaf_faces[q]);
        ++drawn;
        if (!EFTraits::excluded(topo, e, f)) m.ef.process_pair(ctx, {e, f});
      }
    }
    if (run_ee) m.ee.propagate_from(ctx, c_ee);
    if (run_vf) m.vf.propagate_from(ctx, c_vf);
    if (run_ef) m.ef.propagate_from(ctx, c_ef);
    if (out_of_time()) unfinish(z);
  }
  const double search_ms = ms_since(search_start);

  // 4. Kept pairs for the next frame: the engines' near pairs and walks, and the pairs of the
  //    zones not examined, each filed under its zone.
  std::vector<Kept>& kept = m.kept;
  kept.clear();
  const auto file = [&](int type, const std::vector<PrimitivePair>& pairs) {
    for (const PrimitivePair& p : pairs) kept.push_back({m.zone_of(type, p), static_cast<std::uint8_t>(type), p});
  };
  file(kEE, m.ee.near_pairs());
  file(kEE, m.ee.walking_pairs());
  file(kVF, m.vf.near_pairs());
  file(kVF, m.vf.walking_pairs());
  file(kEF, m.ef.near_pairs());
  file(kEF, m.ef.walking_pairs());
  kept.insert(kept.end(), carried.begin(), carried.end());
  std::sort(kept.begin(), kept.end());
  kept.erase(std::unique(kept.begin(), kept.end()), kept.end());

  // 5. The risk report: contacts per zone, ages, estimated misses.
  const auto count = [&](Index la, Index lb) {
    if (la < 0 || lb < 0) return;
    const std::ptrdiff_t i = m.find_zone(pair_key(std::min(la, lb), std::max(la, lb)));
    if (i >= 0) ++m.zones[static_cast<std::size_t>(i)].found;
  };
  const auto at = [](const std::vector<Index>& owner, Index i) { return owner[static_cast<std::size_t>(i)]; };
  for (const auto& c : out.vf) count(at(m.vertex_owner, c.vertex), at(m.face_leaf, c.face));
  for (const auto& c : out.ee) count(at(m.edge_owner, c.edge0), at(m.edge_owner, c.edge1));
  for (const auto& c : out.tt) count(at(m.face_leaf, c.face0), at(m.face_leaf, c.face1));
  double est_missed = 0;
  int oldest = 0;
  std::size_t due_left = 0;
  m.infos.clear();
  for (Zone& z : m.zones) {
    if (z.examined) {
      z.age = 0;
      z.never = false;
      z.contacts = z.found;
    } else {
      est_missed += std::max(0, z.contacts - z.found);
      oldest = std::max(oldest, z.age);
      due_left += due(z) ? 1 : 0;
    }
    m.infos.push_back({z.a, z.b, z.age, z.examined, z.contacts});
  }

  EngineStats total;
  for (const EngineStats* s : {&m.ee.stats(), &m.vf.stats(), &m.ef.stats()}) {
    total.kept += s->kept + s->walking;
    total.converge_steps += s->converge_steps;
    total.distance_evals += s->distance_evals;
    total.propagation_visits += s->propagation_visits;
    total.colliding += s->colliding;
  }
  stats_.set("leaves", nl);
  stats_.set("zones", static_cast<double>(m.zones.size()));
  stats_.set("zones_examined", static_cast<double>(examined));
  stats_.set("zones_due", static_cast<double>(zones_due));
  stats_.set("zones_due_left", static_cast<double>(due_left));
  stats_.set("oldest_zone_age", oldest);
  stats_.set("est_missed", est_missed);
  stats_.set("drawn", drawn);
  stats_.set("kept", static_cast<double>(kept.size()));
  stats_.set("carried", static_cast<double>(carried.size()));
  stats_.set("converge_steps", total.converge_steps);
  stats_.set("distance_evals", total.distance_evals);
  stats_.set("propagation_visits", total.propagation_visits);
  stats_.set("colliding", total.colliding);
  stats_.set("exact_pairs", exact_pairs);
  stats_.set("refit_ms", refit_ms);
  stats_.set("zones_ms", zones_ms);
  stats_.set("search_ms", search_ms);
}

}  // namespace crumple
