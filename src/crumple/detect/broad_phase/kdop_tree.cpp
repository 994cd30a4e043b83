#include <crumple/core/parallel.hpp>
#include <crumple/core/timing.hpp>
#include <crumple/detect/broad_phase/kdop_tree.hpp>
#include <crumple/detect/narrow_phase.hpp>
#include <crumple/geometry/kdop.hpp>

#include <algorithm>
#include <array>
#include <atomic>
#include <bit>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <limits>
#include <mutex>
#include <numbers>
#include <numeric>
#include <span>
#include <string>
#include <utility>
#include <vector>

namespace crumple {

KdopParams KdopParams::from_spec(const MethodSpec& spec) {
  // Keys left out keep the struct's defaults (one place says what they are).
  KdopParams p;
  static constexpr std::array<std::string_view, 4> kK{"6", "14", "18", "26"};
  static constexpr std::array<std::string_view, 3> kArity{"2", "4", "8"};
  p.k = std::stoi(spec.get_choice("k", std::to_string(p.k), kK));
  p.arity = std::stoi(spec.get_choice("arity", std::to_string(p.arity), kArity));
  const long long leaf = spec.get_int("leaf", p.leaf);
  // Saturated to int (a value past it is out of range all the same): `validate` reports it.
  p.leaf = static_cast<int>(
      std::clamp<long long>(leaf, std::numeric_limits<int>::min(), std::numeric_limits<int>::max()));
  p.rebuild = spec.get_double("rebuild", p.rebuild);
  p.sweep = spec.get_bool("sweep", p.sweep);
  p.cones = spec.get_bool("cones", p.cones);
  p.coherence = spec.get_bool("coherence", p.coherence);
  p.exact = ExactParams::from_spec(spec);
  p.validate("method " + spec.to_string());
  return p;
}

void KdopParams::validate(const std::string& who) const {
  if (k != 6 && k != 14 && k != 18 && k != 26) {
    throw InputError(who + ": k must be 6, 14, 18 or 26, got " + std::to_string(k));
  }
  if (arity != 2 && arity != 4 && arity != 8) {
    throw InputError(who + ": arity must be 2, 4 or 8, got " + std::to_string(arity));
  }
  if (leaf < 1 || leaf > 64) throw InputError(who + ": leaf must be in 1..64, got " + std::to_string(leaf));
  if (!(rebuild >= 1)) throw InputError(who + ": rebuild must be >= 1");
}

/// Type-erased hierarchy: one implementation per k.
class KdopTree::Impl {
 public:
  virtual ~Impl() = default;
  virtual void update(const Topology& topo, const FrameInput& in, DetectorStats& stats) = 0;
  virtual void self_pairs(CandidateBuffer& out, DetectorStats& stats) = 0;
  virtual int levels() const = 0;
  virtual std::vector<Bounds> boxes(int depth) const = 0;
  virtual std::vector<std::vector<Index>> leaf_faces() const = 0;
};

namespace {

/// Members per lane group: eight floats / eight lane masks (GCC and Clang vector extensions:
/// one AVX register, or two SSE ones on x86-64 where the traversal's clone without AVX2 runs;
/// NEON pairs on Arm).
constexpr int kGroup = 8;
using F8 = float __attribute__((vector_size(4 * kGroup)));
using I8 = std::int32_t __attribute__((vector_size(4 * kGroup)));
using F4 = float __attribute__((vector_size(16)));

/// Bit l set when lane l of v is 0 (the lanes of a vector comparison are 0 or -1): a sign-mask
/// instruction per half where SSE is there.
__attribute__((always_inline)) inline std::uint64_t zero_lanes(const I8& v) {
#if defined(__SSE__)
  // The halves by shuffles, in registers: a bit_cast to two F4 went through the stack, and
  // the AVX2 clone's 32-byte store then 16-byte loads stalled the store forwarding.
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

/// The traversal's recursive functions and the refit's loop are compiled three times, for
/// x86-64-v4 (AVX-512: the lane comparisons into mask registers), with AVX2 (a lane group in
/// one register) and without, and the CPU picks at load time (GCC's function multiversioning). The
/// library is built with -ffp-contract=off (src/CMakeLists.txt), so that the v4 clone, whose
/// target has FMA, rounds as the others do. Under the sanitizers, one clone: the same source,
/// a third of the compile time (the slowest file of the sanitized build).
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__) && !defined(CRUMPLE_SANITIZED)
#define CRUMPLE_SIMD_CLONES __attribute__((target_clones("arch=x86-64-v4", "avx2", "default")))
#else
#define CRUMPLE_SIMD_CLONES
#endif

/// d as a float, by a non-decreasing map (round to nearest inside the float range, infinity
/// beyond it; NaN stays NaN). Non-decreasing is all the overlap tests need: slabs that overlap
/// in double (lo <= hi') still overlap in float (to_float(lo) <= to_float(hi')), so the float
/// lanes never separate k-DOPs that the double test keeps.
float to_float(double d) {
  constexpr double kMax = std::numeric_limits<float>::max();
  if (d > kMax) return std::numeric_limits<float>::infinity();
  if (d < -kMax) return -std::numeric_limits<float>::infinity();
  return static_cast<float>(d);
}

template <int K>
class DopTree final : public KdopTree::Impl {
  using Dop = geometry::Kdop<K>;
  static constexpr int kAxes = Dop::kAxes;
  /// Up to eight k-DOPs of a node's members (an internal node's children, a leaf's faces) side
  /// by side, one lane each, in float (`to_float`), so that a k-DOP is tested against eight
  /// members with a few vector compares (no branch per slab). Unused lanes are empty (min +inf,
  /// max -inf). Conservative: k-DOPs that overlap in double always overlap here; the face
  /// pairs that pass are then tested in double.
  struct alignas(32) Lanes {
    std::array<F8, kAxes> lo, hi;
  };
  /// A node's or face's k-DOP in float (the query side of a lane test).
  struct FloatDop {
    std::array<float, kAxes> lo, hi;
  };

  /// Temporal coherence (proximity queries, `coherence=on`). A refresh frame inflates every
  /// k-DOP by kSlack times the radius more and records the candidates of each *unit*: the first
  /// self-test of a node of at most kUnitFaces faces, or pair test of two such nodes, that the
  /// traversal reaches (the same units whatever the thread count: tasks are never cut inside
  /// one). A later frame gives each node the box of its vertices' displacements since the
  /// refresh; a unit whose displacements differ by at most the slack s = 2 (refresh radius -
  /// radius) emits the recorded candidates instead of being traversed. Exact: two points of
  /// its faces within the padded thickness now were within it + s on the refresh frame (their
  /// relative position changed by at most s), so their faces' k-DOPs, inflated by half of
  /// that, overlapped then, and the pair was recorded (a unit with no record had none).
  static constexpr Index kUnitFaces = 512;
  static constexpr Scalar kSlack = 1.0 / 16;
  enum class Mode { off, record, reuse };
  /// A recorded unit: candidates unit_pairs_[begin, end) of the nodes key = (min << 32 | max).
  struct Unit {
    std::uint64_t key;
    std::size_t begin, end;
  };
  /// One task's traversal state.
  struct Walk {
    std::vector<FacePair> out;
    std::vector<Unit> units;  ///< refresh frames: its units with candidates, into `pairs`
    std::vector<FacePair> pairs;
    std::size_t reused = 0, live = 0;
  };

  /// Leaf: `first`/`count` index slots of `order_`; internal: child node ids.
  struct Node {
    Index first = 0;
    Index count = 0;
    Index faces = 0;  ///< faces below the node
    bool leaf = false;
    Index slot_begin = 0, slot_end = 0;  ///< the node's faces: slots [slot_begin, slot_end)
    Index lanes = 0;  ///< members first + 8g .. first + 8g + 7 are in lanes_[lanes + g]
  };

 public:
  explicit DopTree(const KdopParams& params) : params_(params) {}

  void update(const Topology& topo, const FrameInput& in, DetectorStats& stats) override {
    threads_ = in.threads;
    if (topo.num_faces() == 0) return;
    const auto t0 = std::chrono::steady_clock::now();
    if (nodes_.empty()) build(topo, in.positions, in.owns, stats);
    const auto tc = std::chrono::steady_clock::now();
    choose_coherence(in);
    stats.set("coherence_ms", ms_since(tc));
    refit(in);
    double q = quality();
    if (q > params_.rebuild * built_quality_) {
      build(topo, in.positions, in.owns, stats);  // the node ids change: the cache is dropped
      if (mode_ == Mode::reuse) start_record(in);
      refit(in);
      q = quality();
    }
    stats.set("refit_ms", ms_since(t0));
    stats.set("quality", q / built_quality_);
    stats.set("nodes", static_cast<double>(nodes_.size()));

    culling_ = params_.cones && in.intersection_only;
    if (culling_) {
      const auto tc = std::chrono::steady_clock::now();
      if (!contours_valid_) build_contours();
      normal_masks(in.positions);
      positions_ = in.positions;
      stats.set("cones_ms", ms_since(tc));
    }
  }

  void self_pairs(CandidateBuffer& out, DetectorStats& stats) override {
    if (nodes_.empty()) return;
    culled_ = 0;
    const auto t1 = std::chrono::steady_clock::now();
    traverse(threads_, out, stats);
    stats.set("traversal_ms", ms_since(t1));
    stats.set("coherence", mode_ == Mode::off ? 0 : mode_ == Mode::record ? 1 : 2);
    if (culling_) stats.set("culled_nodes", static_cast<double>(culled_.load()));
  }

  int levels() const override { return static_cast<int>(levels_.size()); }

  std::vector<Bounds> boxes(int depth) const override {
    std::vector<Bounds> out;
    if (depth < 0 || depth >= levels() || dops_.size() != nodes_.size()) return out;
    const auto [begin, end] = levels_[static_cast<std::size_t>(depth)];
    for (Index n = begin; n < end; ++n) {
      const Dop& d = dops_[static_cast<std::size_t>(n)];
      out.push_back({Vec3(d.min(0), d.min(1), d.min(2)), Vec3(d.max(0), d.max(1), d.max(2))});
    }
    return out;
  }

  std::vector<std::vector<Index>> leaf_faces() const override {
    std::vector<std::vector<Index>> out;
    for (const Node& node : nodes_) {
      if (!node.leaf) continue;
      const auto first = order_.begin() + node.first;
      out.emplace_back(first, first + node.count);
    }
    return out;
  }

 private:
  // ---- build -------------------------------------------------------------------------------
  void build(const Topology& topo, PositionsView x, std::span<const std::uint8_t> owns, DetectorStats& stats) {
    const Index nf = topo.num_faces();
    std::vector<Vec3> centroid(static_cast<std::size_t>(nf));
    for (Index f = 0; f < nf; ++f) {
      const Face& t = topo.face(f);
      centroid[static_cast<std::size_t>(f)] = (narrow::at(x, t[0]) + narrow::at(x, t[1]) + narrow::at(x, t[2])) / 3;
    }
    order_.resize(static_cast<std::size_t>(nf));
    std::iota(order_.begin(), order_.end(), 0);
    // Connected components (by shared vertices), and each one's mean face centroid.
    {
      std::vector<Index> root(static_cast<std::size_t>(topo.num_vertices()));
      std::iota(root.begin(), root.end(), 0);
      const auto find = [&](Index v) {
        while (root[static_cast<std::size_t>(v)] != v) {
          v = root[static_cast<std::size_t>(v)] = root[static_cast<std::size_t>(root[static_cast<std::size_t>(v)])];
        }
        return v;
      };
      for (Index f = 0; f < nf; ++f) {
        const Face& t = topo.face(f);
        for (int k = 1; k < 3; ++k) root[static_cast<std::size_t>(find(t[k]))] = find(t[0]);
      }
      component_.resize(static_cast<std::size_t>(nf));
      component_centroid_.assign(root.size(), Vec3::Zero());
      std::vector<Index> count(root.size(), 0);
      for (Index f = 0; f < nf; ++f) {
        const Index c = find(topo.face(f)[0]);
        component_[static_cast<std::size_t>(f)] = c;
        component_centroid_[static_cast<std::size_t>(c)] += centroid[static_cast<std::size_t>(f)];
        ++count[static_cast<std::size_t>(c)];
      }
      for (std::size_t c = 0; c < root.size(); ++c) {
        if (count[c] > 0) component_centroid_[c] /= static_cast<Scalar>(count[c]);
      }
      component_faces_.assign(root.size(), 0);
    }
    // The patches are grown at the first build only: they are connected pieces of the surface
    // whatever the positions, and growing them is a large part of a build, which a rebuild need
    // not pay again.
    if (patch_.size() != static_cast<std::size_t>(nf)) grow_patches(topo, centroid);
    patch_centroids(centroid);
    nodes_.assign(1, Node{});
    levels_.clear();
    struct Item {
      Index begin, end;
      int depth;
    };
    std::vector<Item> queue{{0, nf, 0}};
    for (std::size_t n = 0; n < queue.size(); ++n) {  // node n is queue item n (breadth-first)
      const Item item = queue[n];
      if (levels_.size() <= static_cast<std::size_t>(item.depth)) {
        levels_.push_back({static_cast<Index>(n), static_cast<Index>(n)});
      }
      levels_[static_cast<std::size_t>(item.depth)][1] = static_cast<Index>(n + 1);
      const Index size = item.end - item.begin;
      Node& node = nodes_[n];
      node.faces = size;
      // A node of one patch is a leaf (the cuts keep patches whole; a patch has at most
      // `leaf` faces).
      const auto one_patch = [&] {
        const Index p = patch_[static_cast<std::size_t>(order_[static_cast<std::size_t>(item.begin)])];
        return std::all_of(order_.begin() + item.begin, order_.begin() + item.end,
                           [&](Index f) { return patch_[static_cast<std::size_t>(f)] == p; });
      };
      if (size <= params_.leaf && one_patch()) {
        node = {item.begin, size, size, true, item.begin, item.end};
        group_leaf(centroid, item.begin, item.end);
        continue;
      }
      // The children come from recursive halving, each half cut across its own longest
      // centroid extent: a 4-ary node gets roughly square children, not four parallel slabs,
      // so fewer sibling pairs overlap along long shared boundaries. The cuts keep patches
      // whole, so a node of two patches has two children whatever the arity.
      std::vector<Index> cuts{item.begin};
      split(centroid, item.begin, item.end, std::min<Index>(params_.arity, size), cuts);
      const Index parts = static_cast<Index>(cuts.size()) - 1;
      const Index first = static_cast<Index>(nodes_.size());
      node = {first, parts, size, false, item.begin, item.end};
      for (Index i = 0; i < parts; ++i) {
        queue.push_back({cuts[static_cast<std::size_t>(i)], cuts[static_cast<std::size_t>(i) + 1], item.depth + 1});
        nodes_.push_back(Node{});
      }
    }
    // The component and patch-centroid scratch serves the cuts only (the patches are kept).
    patch_centroid_ = {};
    component_ = {};
    component_centroid_ = {};
    component_faces_ = {};
    scratch_ = {};
    Index groups = 0;
    for (Node& node : nodes_) {
      node.lanes = groups;
      groups += (node.count + kGroup - 1) / kGroup;
    }
    lanes_.assign(static_cast<std::size_t>(groups), Lanes{});
    float_dops_.assign(nodes_.size(), FloatDop{});
    slot_faces_.resize(order_.size());
    for (std::size_t s = 0; s < order_.size(); ++s) slot_faces_[s] = topo.face(order_[s]);
    // Within a leaf, which faces share a vertex: the leaf's self-test skips them by mask.
    leaf_adjacent_.assign(order_.size(), 0);
    for (const Node& node : nodes_) {
      if (!node.leaf) continue;
      for (Index i = 0; i < node.count; ++i) {
        for (Index j = 0; j < node.count; ++j) {
          const auto si = static_cast<std::size_t>(node.first + i), sj = static_cast<std::size_t>(node.first + j);
          if (i != j && faces_share_vertex(slot_faces_[si], slot_faces_[sj])) leaf_adjacent_[si] |= std::uint64_t{1} << j;
        }
      }
    }
    // What the faces own (FrameInput::owns), per slot, and per leaf the members owning no
    // vertex, no edge: the pairs that own no sub-pair are left out.
    slot_owns_.clear();
    leaf_no_vertex_.assign(nodes_.size(), 0);
    leaf_no_edge_.assign(nodes_.size(), 0);
    if (!owns.empty()) {
      slot_owns_.resize(order_.size());
      for (std::size_t s = 0; s < order_.size(); ++s) slot_owns_[s] = owns[static_cast<std::size_t>(order_[s])];
      for (std::size_t n = 0; n < nodes_.size(); ++n) {
        const Node& node = nodes_[n];
        if (!node.leaf) continue;
        for (Index i = 0; i < node.count; ++i) {
          const std::uint8_t o = slot_owns_[static_cast<std::size_t>(node.first + i)];
          leaf_no_vertex_[n] |= static_cast<std::uint64_t>((o & 1u) == 0) << i;
          leaf_no_edge_[n] |= static_cast<std::uint64_t>((o & 2u) == 0) << i;
        }
      }
    }
    dops_.assign(nodes_.size(), Dop());
    level_leaf_faces_.assign(levels_.size(), 0);
    for (std::size_t l = 0; l < levels_.size(); ++l) {
      for (Index n = levels_[l][0]; n < levels_[l][1]; ++n) {
        if (nodes_[static_cast<std::size_t>(n)].leaf) level_leaf_faces_[l] += nodes_[static_cast<std::size_t>(n)].faces;
      }
    }
    small_.resize(nodes_.size());
    leaf_ids_.clear();
    leaf_verts_.assign(nodes_.size() + 1, 0);
    verts_.clear();
    for (std::size_t n = 0; n < nodes_.size(); ++n) {
      const Node& node = nodes_[n];
      small_[n] = node.faces <= kUnitFaces ? 1 : 0;
      if (node.leaf) {
        leaf_ids_.push_back(static_cast<Index>(n));
        const std::size_t first = verts_.size();
        for (Index s = node.first; s < node.first + node.count; ++s) {
          for (const Index v : slot_faces_[static_cast<std::size_t>(s)]) verts_.push_back(v);
        }
        std::sort(verts_.begin() + static_cast<std::ptrdiff_t>(first), verts_.end());
        verts_.erase(std::unique(verts_.begin() + static_cast<std::ptrdiff_t>(first), verts_.end()), verts_.end());
      }
      leaf_verts_[n + 1] = verts_.size();
    }
    cache_valid_ = false;
    built_quality_ = 0;  // set by the first refit
    contours_valid_ = false;
    stats.add("rebuilds", 1);
  }

  /// Cuts the faces into connected patches of at most `leaf` faces (faces sharing a vertex are
  /// connected), the leaves to be: each grown from a seed, the first face not yet in a patch in
  /// Morton order of the centroids, by adding the face nearest to the seed among those that
  /// share a vertex with the patch (of a vertex's first 256 faces); then a patch of fewer than leaf / 4 faces joins the smallest
  /// patch it touches that has room. A leaf of one patch stays compact however its surface
  /// moves; a leaf of median cuts may hold pieces of surfaces that only pass near each other,
  /// and those pieces move apart, loosening the refitted tree. Sets `patch_` and
  /// `patches_`; `patch_centroids` then gives the cuts their keys.
  void grow_patches(const Topology& topo, const std::vector<Vec3>& centroid) {
    const std::size_t nf = centroid.size();
    Vec3 lo = Vec3::Constant(std::numeric_limits<Scalar>::infinity());
    Vec3 hi = -lo;
    for (const Vec3& c : centroid) {
      if (!c.allFinite()) continue;
      lo = lo.cwiseMin(c);
      hi = hi.cwiseMax(c);
    }
    const Vec3 scale = (hi - lo).cwiseMax(Vec3::Constant(std::numeric_limits<Scalar>::min())).cwiseInverse() * 1023;
    const auto spread = [](std::uint32_t v) {  // 10 bits to every third of 30
      std::uint64_t x = v & 0x3FFu;
      x = (x | x << 16) & 0x30000FFull;
      x = (x | x << 8) & 0x300F00Full;
      x = (x | x << 4) & 0x30C30C3ull;
      return (x | x << 2) & 0x9249249ull;
    };
    std::vector<std::pair<std::uint64_t, Index>> seeds(nf);
    for (std::size_t f = 0; f < nf; ++f) {
      std::uint64_t code = 0;
      for (int a = 0; a < 3; ++a) {
        const Scalar t = (centroid[f][a] - lo[a]) * scale[a];
        const auto q = static_cast<std::uint32_t>(t >= 0 && t <= 1023 ? t : 0);  // NaN: 0
        code |= spread(q) << a;
      }
      seeds[f] = {code, static_cast<Index>(f)};
    }
    std::sort(seeds.begin(), seeds.end());
    constexpr Index kNone = -1;
    patch_.assign(nf, kNone);
    std::vector<Index> size;
    struct Frontier {
      Scalar d2;
      Index face;
      bool operator<(const Frontier& o) const { return d2 > o.d2 || (d2 == o.d2 && face > o.face); }  // min-heap
    };
    std::vector<Frontier> heap;
    std::vector<Index> offered;  // faces pushed for this patch, to forget after it
    std::vector<char> seen(nf, 0);
    // The faces sharing a vertex with f, from each corner's first kNearScan faces: the same
    // set as `face_faces` at ordinary valences (the heap's order and the merge's choice do not
    // depend on the order of offers), without its memory quadratic in a valence (issue 45: a
    // fan of n faces has n^2 face pairs); past the cap a patch is only less compact.
    constexpr std::size_t kNearScan = 256;
    const Adjacency& vertex_faces = topo.vertex_faces();
    const auto for_near = [&](Index f, const auto& visit) {
      for (const Index v : topo.face(f)) {
        const auto around = vertex_faces[v];
        const std::size_t n = std::min(around.size(), kNearScan);
        for (std::size_t i = 0; i < n; ++i) {
          if (around[i] != f) visit(around[i]);
        }
      }
    };
    for (const auto& [code, seed] : seeds) {
      if (patch_[static_cast<std::size_t>(seed)] != kNone) continue;
      const auto id = static_cast<Index>(size.size());
      size.push_back(0);
      const Vec3 c = centroid[static_cast<std::size_t>(seed)];
      const auto d2 = [&](Index f) {
        const Scalar d = (centroid[static_cast<std::size_t>(f)] - c).squaredNorm();
        return d == d ? d : std::numeric_limits<Scalar>::infinity();
      };
      heap.assign(1, {0, seed});
      offered.assign(1, seed);
      seen[static_cast<std::size_t>(seed)] = 1;
      while (!heap.empty() && size.back() < params_.leaf) {
        std::pop_heap(heap.begin(), heap.end());
        const Index f = heap.back().face;
        heap.pop_back();
        patch_[static_cast<std::size_t>(f)] = id;
        ++size.back();
        for_near(f, [&](Index g) {
          if (patch_[static_cast<std::size_t>(g)] != kNone || seen[static_cast<std::size_t>(g)] != 0) return;
          seen[static_cast<std::size_t>(g)] = 1;
          offered.push_back(g);
          heap.push_back({d2(g), g});
          std::push_heap(heap.begin(), heap.end());
        });
      }
      for (const Index f : offered) seen[static_cast<std::size_t>(f)] = 0;
    }
    // Small patches join a neighbour: the smallest that has room.
    const auto patches = size.size();
    std::vector<std::vector<Index>> members(patches);
    for (std::size_t f = 0; f < nf; ++f) members[static_cast<std::size_t>(patch_[f])].push_back(static_cast<Index>(f));
    for (std::size_t p = 0; p < patches; ++p) {
      const Index n = size[p];
      if (n == 0 || 4 * n >= params_.leaf) continue;
      Index best = kNone;
      for (const Index f : members[p]) {
        for_near(f, [&](Index g) {
          const Index q = patch_[static_cast<std::size_t>(g)];
          if (static_cast<std::size_t>(q) == p || size[static_cast<std::size_t>(q)] + n > params_.leaf) return;
          if (best == kNone || size[static_cast<std::size_t>(q)] < size[static_cast<std::size_t>(best)] ||
              (size[static_cast<std::size_t>(q)] == size[static_cast<std::size_t>(best)] && q < best)) {
            best = q;
          }
        });
      }
      if (best == kNone) continue;
      for (const Index f : members[p]) patch_[static_cast<std::size_t>(f)] = best;
      auto& into = members[static_cast<std::size_t>(best)];
      into.insert(into.end(), members[p].begin(), members[p].end());
      members[p].clear();
      size[static_cast<std::size_t>(best)] += n;
      size[p] = 0;
    }
    patches_ = patches;
  }

  /// Each patch's mean face centroid at this build's positions, of the finite centroids (a NaN
  /// one would make every comparison of the cuts false).
  void patch_centroids(const std::vector<Vec3>& centroid) {
    patch_centroid_.assign(patches_, Vec3::Zero());
    std::vector<Index> finite(patches_, 0);
    for (std::size_t f = 0; f < centroid.size(); ++f) {
      const Vec3& c = centroid[f];
      if (!c.allFinite()) continue;
      const auto p = static_cast<std::size_t>(patch_[f]);
      patch_centroid_[p] += c;
      ++finite[p];
    }
    for (std::size_t p = 0; p < patches_; ++p) {
      if (finite[p] > 0) patch_centroid_[p] /= static_cast<Scalar>(finite[p]);
    }
  }

  /// The axis of the largest extent of the centroids of the faces in slots [begin, end).
  int longest_axis(const std::vector<Vec3>& centroid, Index begin, Index end) const {
    Vec3 lo = Vec3::Constant(std::numeric_limits<Scalar>::infinity());
    Vec3 hi = -lo;
    for (Index i = begin; i < end; ++i) {
      const Vec3& c = centroid[static_cast<std::size_t>(order_[static_cast<std::size_t>(i)])];
      lo = lo.cwiseMin(c);
      hi = hi.cwiseMax(c);
    }
    int axis = 0;
    (hi - lo).maxCoeff(&axis);
    return axis;
  }

  /// Orders a leaf's slots [begin, end) so that each lane group of kGroup faces is a compact
  /// piece of the leaf (recursive halving at multiples of kGroup, across the longest centroid
  /// extent): a k-DOP that overlaps part of the leaf then meets few of its groups.
  void group_leaf(const std::vector<Vec3>& centroid, Index begin, Index end) {
    const Index groups = (end - begin + kGroup - 1) / kGroup;
    if (groups <= 1) return;
    const int axis = longest_axis(centroid, begin, end);
    const Index mid = begin + kGroup * (groups / 2);
    std::nth_element(order_.begin() + begin, order_.begin() + mid, order_.begin() + end, [&](Index a, Index b) {
      const Scalar ca = centroid[static_cast<std::size_t>(a)][axis];
      const Scalar cb = centroid[static_cast<std::size_t>(b)][axis];
      return ca < cb || (ca == cb && a < b);
    });
    group_leaf(centroid, begin, mid);
    group_leaf(centroid, mid, end);
  }

  /// Cuts the slots [begin, end) into at most `parts` ranges of near-equal size by recursive
  /// halving at the median patch centroid along the longest extent of each half, each cut moved
  /// to the nearer end of the patch it falls in (a range of one patch is not cut); appends the
  /// ends to `cuts`.
  void split(const std::vector<Vec3>& centroid, Index begin, Index end, Index parts, std::vector<Index>& cuts) {
    if (parts <= 1) {
      cuts.push_back(end);
      return;
    }
    const int axis = longest_axis(centroid, begin, end);
    // Ordered by their patch's centroid (then patch), so that a patch's faces are equal.
    const auto patch = [&](Index f) { return patch_[static_cast<std::size_t>(f)]; };
    const auto less = [&](Index a, Index b) {
      const Index pa = patch(a), pb = patch(b);
      const Scalar ca = patch_centroid_[static_cast<std::size_t>(pa)][axis];
      const Scalar cb = patch_centroid_[static_cast<std::size_t>(pb)][axis];
      return ca < cb || (ca == cb && pa < pb);
    };
    const Index left = parts / 2;
    Index mid = begin + static_cast<Index>(static_cast<long long>(end - begin) * left / parts);
    const Index at = component_cut(centroid, begin, end, mid, axis);
    if (at >= 0) {
      mid = at;
    } else {
      std::nth_element(order_.begin() + begin, order_.begin() + mid, order_.begin() + end, less);
      // The patch at the median gathered on both sides of it; the cut goes at its nearer end
      // that leaves both sides some faces (one patch only: no cut).
      const Index p = patch(order_[static_cast<std::size_t>(mid)]);
      const Index lower = static_cast<Index>(
          std::partition(order_.begin() + begin, order_.begin() + mid, [&](Index f) { return patch(f) != p; }) -
          order_.begin());
      const Index upper = static_cast<Index>(
          std::partition(order_.begin() + mid, order_.begin() + end, [&](Index f) { return patch(f) == p; }) -
          order_.begin());
      const bool can_lower = lower > begin, can_upper = upper < end;
      if (!can_lower && !can_upper) {
        cuts.push_back(end);
        return;
      }
      mid = can_lower && (!can_upper || mid - lower <= upper - mid) ? lower : upper;
    }
    split(centroid, begin, mid, left, cuts);
    split(centroid, mid, end, parts - left, cuts);
  }

  /// Where the faces of slots [begin, end) belong to several connected components, a cut
  /// between components, so that a node does not mix small bodies that move apart (a unit of
  /// the frame-to-frame cache that mixes them cannot be reused). Only where every component in the
  /// node fits in a unit (a larger one is cut across units anyway). Along each
  /// axis (the longest first), the components are ordered by their centroids and the boundary
  /// nearest `mid` that leaves each side at least a quarter of the faces is compared with the
  /// median cut along that axis: kept when it puts at most a quarter of the faces on the other
  /// side (separate or stacked bodies; not intertwined rods, which it would cut lengthwise:
  /// rod-twist's traversal took 8% longer with those cuts). The axis moving the fewest wins.
  /// Returns the cut, with the slots partitioned, or -1 (then the median cut is made).
  Index component_cut(const std::vector<Vec3>& centroid, Index begin, Index end, Index mid, int longest) {
    const auto first = order_.begin() + begin, last = order_.begin() + end;
    const auto comp = [&](Index f) { return static_cast<std::size_t>(component_[static_cast<std::size_t>(f)]); };
    if (std::all_of(first, last, [&](Index f) { return comp(f) == comp(*first); })) return -1;
    struct Piece {
      Index component, faces;
    };
    std::vector<Piece> pieces;
    for (auto it = first; it != last; ++it) {
      if (component_faces_[comp(*it)]++ == 0) pieces.push_back({static_cast<Index>(comp(*it)), 0});
    }
    Index largest = 0;
    for (Piece& p : pieces) {
      p.faces = component_faces_[static_cast<std::size_t>(p.component)];
      component_faces_[static_cast<std::size_t>(p.component)] = 0;
      largest = std::max(largest, p.faces);
    }
    if (largest > kUnitFaces) return -1;
    const Index size = end - begin;
    Index best_at = -1, best_moved = size;
    std::vector<Index> best_left;
    for (const int axis : {longest, (longest + 1) % 3, (longest + 2) % 3}) {
      std::sort(pieces.begin(), pieces.end(), [&](const Piece& p, const Piece& q) {
        const Scalar cp = component_centroid_[static_cast<std::size_t>(p.component)][axis];
        const Scalar cq = component_centroid_[static_cast<std::size_t>(q.component)][axis];
        return cp < cq || (cp == cq && p.component < q.component);
      });
      Index at = begin, cut = -1;
      std::size_t rank = 0;
      for (std::size_t r = 0; r + 1 < pieces.size(); ++r) {
        at += pieces[r].faces;
        const bool balanced = 4 * static_cast<long long>(at - begin) >= size && 4 * static_cast<long long>(end - at) >= size;
        if (balanced && (cut < 0 || std::abs(at - mid) < std::abs(cut - mid))) {
          cut = at;
          rank = r;
        }
      }
      if (cut < 0) continue;
      for (std::size_t r = 0; r <= rank; ++r) component_faces_[static_cast<std::size_t>(pieces[r].component)] = 1;
      scratch_.clear();
      for (auto it = first; it != last; ++it) scratch_.push_back(centroid[static_cast<std::size_t>(*it)][axis]);
      const auto median = scratch_.begin() + (mid - begin);
      std::nth_element(scratch_.begin(), median, scratch_.end());
      Index moved = 0;
      for (auto it = first; it != last; ++it) {
        const bool left_side = component_faces_[comp(*it)] == 1;
        moved += left_side == (centroid[static_cast<std::size_t>(*it)][axis] < *median) ? 0 : 1;
      }
      for (std::size_t r = 0; r <= rank; ++r) component_faces_[static_cast<std::size_t>(pieces[r].component)] = 0;
      if (4 * static_cast<long long>(moved) <= size && moved < best_moved) {
        best_at = cut;
        best_moved = moved;
        best_left.clear();
        for (std::size_t r = 0; r <= rank; ++r) best_left.push_back(pieces[r].component);
      }
    }
    if (best_at < 0) return -1;
    for (const Index c : best_left) component_faces_[static_cast<std::size_t>(c)] = 1;
    std::partition(first, last, [&](Index f) { return component_faces_[comp(f)] == 1; });
    for (const Index c : best_left) component_faces_[static_cast<std::size_t>(c)] = 0;
    return best_at;
  }

  // ---- normal-cone culling -------------------------------------------------------------------
  /// The 26 fixed directions: (i, j, k) in {-1, 0, 1}^3 minus the origin, normalised.
  static const std::array<Vec3, 26>& directions() {
    static const std::array<Vec3, 26> table = [] {
      std::array<Vec3, 26> t{};
      int n = 0;
      for (int i = -1; i <= 1; ++i) {
        for (int j = -1; j <= 1; ++j) {
          for (int k = -1; k <= 1; ++k) {
            if (i != 0 || j != 0 || k != 0) t[static_cast<std::size_t>(n++)] = Vec3(i, j, k).normalized();
          }
        }
      }
      return t;
    }();
    return table;
  }

  /// Per node, the directed boundary edges of its faces (a face's sides in winding order whose
  /// reverse is not a side of another face of the node), and whether the node is cullable at
  /// all (no directed side used twice: consistently oriented and manifold inside the node).
  void build_contours() {
    contour_offsets_.assign(nodes_.size() + 1, 0);
    contour_edges_.clear();
    cullable_.assign(nodes_.size(), 0);
    std::vector<std::uint64_t> keys;
    const auto key = [](Index a, Index b) {
      return (static_cast<std::uint64_t>(static_cast<std::uint32_t>(a)) << 32) | static_cast<std::uint32_t>(b);
    };
    for (std::size_t n = 0; n < nodes_.size(); ++n) {
      const Node& node = nodes_[n];
      keys.clear();
      for (Index s = node.slot_begin; s < node.slot_end; ++s) {
        const Face& t = slot_faces_[static_cast<std::size_t>(s)];
        keys.push_back(key(t[0], t[1]));
        keys.push_back(key(t[1], t[2]));
        keys.push_back(key(t[2], t[0]));
      }
      std::sort(keys.begin(), keys.end());
      bool ok = std::adjacent_find(keys.begin(), keys.end()) == keys.end();
      if (ok) {
        for (const std::uint64_t k : keys) {
          const Index a = static_cast<Index>(k >> 32), b = static_cast<Index>(k & 0xffffffffu);
          if (!std::binary_search(keys.begin(), keys.end(), key(b, a))) contour_edges_.push_back({a, b});
        }
      }
      cullable_[n] = ok ? 1 : 0;
      contour_offsets_[n + 1] = static_cast<Index>(contour_edges_.size());
    }
    contours_valid_ = true;
  }

  /// Bit j of a face's mask: its normal makes a positive angle (margin 1e-3) with direction j;
  /// a node's mask is the AND of its faces'. Degenerate faces have mask 0.
  void normal_masks(PositionsView x) {
    const auto& dirs = directions();
    face_masks_.resize(order_.size());
    for (std::size_t s = 0; s < order_.size(); ++s) {
      const Face& t = slot_faces_[s];
      const Vec3 a = narrow::at(x, t[0]);
      const Vec3 n = (narrow::at(x, t[1]) - a).cross(narrow::at(x, t[2]) - a);
      const Scalar len = n.norm();
      std::uint32_t mask = 0;
      if (len > 0 && std::isfinite(len)) {
        for (std::size_t j = 0; j < dirs.size(); ++j) {
          if (n.dot(dirs[j]) > 1e-3 * len) mask |= 1u << j;
        }
      }
      face_masks_[s] = mask;
    }
    node_masks_.assign(nodes_.size(), 0);
    for (std::size_t l = levels_.size(); l-- > 0;) {
      for (Index n = levels_[l][0]; n < levels_[l][1]; ++n) {
        const Node& node = nodes_[static_cast<std::size_t>(n)];
        std::uint32_t mask = ~0u;
        if (node.leaf) {
          for (Index s = node.first; s < node.first + node.count; ++s) mask &= face_masks_[static_cast<std::size_t>(s)];
        } else {
          for (Index c = node.first; c < node.first + node.count; ++c) mask &= node_masks_[static_cast<std::size_t>(c)];
        }
        node_masks_[static_cast<std::size_t>(n)] = mask;
      }
    }
  }

  /// Whether node n provably cannot intersect itself: every face faces direction V (mask) and
  /// the boundary projected along V is one loop, star-shaped around the mean of its vertices
  /// and traversed once counter-clockwise; then the projection is one-to-one (the number of
  /// preimages of a point is the boundary's winding number around it, 0 or 1), so no two points
  /// of the node coincide. Tries up to four directions of the mask.
  bool culled(Index n) const {
    if (!culling_) return false;
    const std::size_t i = static_cast<std::size_t>(n);
    std::uint32_t mask = node_masks_[i];
    if (mask == 0 || !cullable_[i]) return false;
    const Index begin = contour_offsets_[i], end = contour_offsets_[i + 1];
    if (end - begin < 3) return false;
    const auto& dirs = directions();
    for (int attempt = 0; attempt < 4 && mask != 0; ++attempt) {
      const int j = std::countr_zero(mask);
      mask &= mask - 1;
      const Vec3& v = dirs[static_cast<std::size_t>(j)];
      const Vec3 u = (std::abs(v.x()) < 0.9 ? Vec3::UnitX() : Vec3::UnitY()).cross(v).normalized();
      const Vec3 w = v.cross(u);
      const auto project = [&](Index p) {
        const Vec3& q = narrow::at(positions_, p);
        return std::array<Scalar, 2>{q.dot(u), q.dot(w)};
      };
      std::array<Scalar, 2> c{0, 0};
      for (Index e = begin; e < end; ++e) {
        const auto p = project(contour_edges_[static_cast<std::size_t>(e)][0]);
        c[0] += p[0];
        c[1] += p[1];
      }
      c[0] /= static_cast<Scalar>(end - begin);
      c[1] /= static_cast<Scalar>(end - begin);
      Scalar turn = 0;
      bool star = true;
      for (Index e = begin; e < end && star; ++e) {
        const auto& edge = contour_edges_[static_cast<std::size_t>(e)];
        const auto p = project(edge[0]), q = project(edge[1]);
        const Scalar ax = p[0] - c[0], ay = p[1] - c[1], bx = q[0] - c[0], by = q[1] - c[1];
        const Scalar cross = ax * by - ay * bx, dot = ax * bx + ay * by;
        star = cross > 1e-9 * std::hypot(ax, ay) * std::hypot(bx, by);
        turn += std::atan2(cross, dot);
      }
      if (star && std::abs(turn - 2 * std::numbers::pi) < 1e-3) {
        ++culled_;
        return true;
      }
    }
    return false;
  }

  // ---- refit -------------------------------------------------------------------------------
  void refit(const FrameInput& in) {
    const bool swept = (params_.sweep || in.continuous) && !in.previous.empty();
    // A continuous query's candidates cover the whole motion: no current-position filter.
    swept_ = swept && !in.continuous;
    if (swept) now_dops_.resize(order_.size());
    const Scalar radius = refit_radius_;
    const bool moves = mode_ == Mode::reuse;  // displacement boxes since the refresh frame
    if (moves) moved_.resize(nodes_.size());
    for (std::size_t l = levels_.size(); l-- > 0;) {
      const auto [lb, le] = levels_[l];
      const auto count = static_cast<std::size_t>(le - lb);
      // Chunks of about 2048 leaf faces, and of at most 64 nodes: a level that holds few leaves
      // is mostly inner nodes, which would otherwise be one chunk while the other threads wait.
      const auto leaf_faces = static_cast<std::size_t>(level_leaf_faces_[l]);
      const std::size_t grain = std::clamp<std::size_t>(leaf_faces > 0 ? 2048 * count / leaf_faces : 64, 1, 64);
      parallel_for_chunks(count, in.threads, grain, [&](std::size_t begin, std::size_t end) {
        const auto first = static_cast<std::size_t>(levels_[l][0]);  // clang 14 cannot capture `lb`
        refit_nodes(first + begin, first + end, in, swept, radius, moves);
      });
    }
    if (built_quality_ == 0) built_quality_ = std::max(quality(), 1e-300);
  }

  /// Refits nodes [first, last) of one level, whose children (if any) are refitted.
  CRUMPLE_SIMD_CLONES void refit_nodes(std::size_t first, std::size_t last, const FrameInput& in, bool swept,
                                       Scalar radius, bool moves) {
    std::array<FloatDop, 64> faces;  // a leaf's face k-DOPs, for its lanes
    for (std::size_t n = first; n < last; ++n) {
      const Node& node = nodes_[n];
      Dop d;
      Box mv = Box::empty();
      if (node.leaf) {
        d = refit_leaf_lanes(node, in, swept, radius, faces.data());
        if (moves) {
          for (std::size_t k = leaf_verts_[n]; k < leaf_verts_[n + 1]; ++k) {
            const auto v = static_cast<std::size_t>(verts_[k]);
            mv.grow(in.positions[v] - cache_ref_[v]);
          }
        }
      } else {
        for (Index c = node.first; c < node.first + node.count; ++c) d.merge(dops_[static_cast<std::size_t>(c)]);
        if (moves) {
          for (Index c = node.first; c < node.first + node.count; ++c) mv.merge(moved_[static_cast<std::size_t>(c)]);
        }
        fill_lanes(node, &float_dops_[static_cast<std::size_t>(node.first)]);
      }
      dops_[n] = d;
      if (moves) moved_[n] = mv;
      float_dops_[n] = float_dop(d);
    }
  }

  /// Requests the corners of the face four slots after slot s (in this leaf or the next): a
  /// face's slabs are too many instructions for the out-of-order window to reach the next faces'
  /// loads (the first corner's load was the refit's hottest instruction).
  void prefetch_corners_ahead(std::span<const Vec3> x, Index s) const {
    if (const auto ahead = static_cast<std::size_t>(s) + 4; ahead < slot_faces_.size()) {
      for (const Index v : slot_faces_[ahead]) __builtin_prefetch(&x[static_cast<std::size_t>(v)]);
    }
  }

  /// Leaf `node`'s k-DOP, and its faces' float k-DOPs into its lanes (through `faces`, scratch
  /// for up to 64 float k-DOPs, except on `refit_leaf18`'s path).
  __attribute__((always_inline)) Dop refit_leaf_lanes(const Node& node, const FrameInput& in, bool swept,
                                                      Scalar radius, FloatDop* faces) {
    if constexpr (K == 18) {
      if (!swept) return refit_leaf18(node, in.positions, radius);
    }
    const Dop d = refit_leaf(node, in, swept, radius, faces);
    fill_lanes(node, faces);
    return d;
  }

  /// Leaf `node`'s k-DOP, and its faces' float k-DOPs into `faces` (and their k-DOPs at the
  /// current positions into `now_dops_` when swept).
  __attribute__((always_inline)) Dop refit_leaf(const Node& node, const FrameInput& in, bool swept, Scalar radius,
                                                FloatDop* faces) {
    Dop d;
    // Each face's k-DOP straight from its corners (and their previous positions when
    // swept), inflated: the same slabs as merging per-vertex k-DOPs, since rounding
    // is monotone, without writing and re-reading those.
    for (Index s = node.first; s < node.first + node.count; ++s) {
      const Face& t = slot_faces_[static_cast<std::size_t>(s)];
      prefetch_corners_ahead(in.positions, s);
      Dop f;
      for (const Index v : t) f.extend(in.positions[static_cast<std::size_t>(v)]);
      if (swept) {
        Dop now = f;
        now.inflate(radius);
        now_dops_[static_cast<std::size_t>(s)] = now;
        for (const Index v : t) f.extend(in.previous[static_cast<std::size_t>(v)]);
      }
      f.inflate(radius);
      d.merge(f);
      faces[s - node.first] = float_dop(f);
    }
    return d;
  }

  /// `refit_leaf` then `fill_lanes` for the default k = 18 without sweep, the faces' float
  /// k-DOPs written straight into the leaf's lanes (through a copy they were a third of the
  /// refit's time), two slabs per SSE2 operation: the same
  /// slabs as the generic path, bit for bit (the projections by the same operations as
  /// `Kdop::along`, x - y as x + (-y), which IEEE defines it to be; minima and maxima that skip
  /// a NaN corner like `extend`; then `inflate`, `merge`, `to_float`). The generic path's scalar
  /// slabs were most of the refit's time.
  __attribute__((always_inline)) Dop refit_leaf18(const Node& node, std::span<const Vec3> x, Scalar radius)
    requires(K == 18)
  {
    using D2 = double __attribute__((vector_size(16)));
    constexpr double r2 = 0.70710678118654752440;  // as in Kdop::along
    constexpr double inf = std::numeric_limits<double>::infinity();
    constexpr double kMax = std::numeric_limits<float>::max();
    // Lanes: [x, y], [z, z], [x + y, x - y], [x + z, x - z], [y + z, y - z] (the last three
    // times r2): axes 0, 1 | 2 | 3, 4 | 5, 6 | 7, 8.
    constexpr std::size_t kPairs = 5;
    const auto project = [](const Vec3& p) {
      const double px = p.x(), py = p.y(), pz = p.z();
      return std::array<D2, kPairs>{D2{px, py}, D2{pz, pz}, (D2{px, px} + D2{py, -py}) * r2,
                                    (D2{px, px} + D2{pz, -pz}) * r2, (D2{py, py} + D2{pz, -pz}) * r2};
    };
    // Slab j of the lanes, by the pair layout above.
    const auto lane = [](const std::array<D2, kPairs>& v, int j) {
      return j < 3 ? v[static_cast<std::size_t>(j / 2)][j % 2] : v[static_cast<std::size_t>((j + 1) / 2)][(j + 1) % 2];
    };
    const auto rounded = [&](D2 v) {  // to_float's clamp, before the conversion
      v = v > kMax ? D2{} + inf : v;
      return v < -kMax ? D2{} - inf : v;
    };
    std::array<D2, kPairs> node_lo, node_hi;
    node_lo.fill(D2{} + inf);
    node_hi.fill(D2{} - inf);
    for (Index s = node.first; s < node.first + node.count; ++s) {
      prefetch_corners_ahead(x, s);
      std::array<D2, kPairs> lo, hi;
      lo.fill(D2{} + inf);
      hi.fill(D2{} - inf);
      for (const Index v : slot_faces_[static_cast<std::size_t>(s)]) {
        const auto q = project(x[static_cast<std::size_t>(v)]);
        for (std::size_t k = 0; k < kPairs; ++k) {
          lo[k] = q[k] < lo[k] ? q[k] : lo[k];
          hi[k] = hi[k] < q[k] ? q[k] : hi[k];
        }
      }
      const auto member = static_cast<std::size_t>(s - node.first);
      Lanes& lanes = lanes_[static_cast<std::size_t>(node.lanes) + member / kGroup];
      const std::size_t l = member % kGroup;
      std::array<D2, kPairs> flo, fhi;
      for (std::size_t k = 0; k < kPairs; ++k) {
        lo[k] -= radius;
        hi[k] += radius;
        node_lo[k] = lo[k] < node_lo[k] ? lo[k] : node_lo[k];
        node_hi[k] = node_hi[k] < hi[k] ? hi[k] : node_hi[k];
        flo[k] = rounded(lo[k]);
        fhi[k] = rounded(hi[k]);
      }
      for (int j = 0; j < kAxes; ++j) {
        lanes.lo[static_cast<std::size_t>(j)][l] = static_cast<float>(lane(flo, j));
        lanes.hi[static_cast<std::size_t>(j)][l] = static_cast<float>(lane(fhi, j));
      }
    }
    empty_lanes_past_members(node);
    typename Dop::Slabs mins, maxs;
    for (int j = 0; j < kAxes; ++j) {
      mins[static_cast<std::size_t>(j)] = lane(node_lo, j);
      maxs[static_cast<std::size_t>(j)] = lane(node_hi, j);
    }
    return Dop::from_slabs(mins, maxs);
  }

  static FloatDop float_dop(const Dop& d) {
    FloatDop f;
    for (int j = 0; j < kAxes; ++j) {
      f.lo[static_cast<std::size_t>(j)] = to_float(d.min(j));
      f.hi[static_cast<std::size_t>(j)] = to_float(d.max(j));
    }
    return f;
  }

  /// Writes the float k-DOPs of the node's members (faces of a leaf, children otherwise),
  /// `members[0, count)`, into its lanes, eight per group; lanes past `count` are empty.
  void fill_lanes(const Node& node, const FloatDop* members) {
    for (Index i = 0; i < node.count; ++i) {
      Lanes& lanes = lanes_[static_cast<std::size_t>(node.lanes + i / kGroup)];
      const auto l = static_cast<std::size_t>(i % kGroup);
      const FloatDop& f = members[i];
      for (std::size_t j = 0; j < static_cast<std::size_t>(kAxes); ++j) {
        lanes.lo[j][l] = f.lo[j];
        lanes.hi[j][l] = f.hi[j];
      }
    }
    empty_lanes_past_members(node);
  }

  /// Empties (min +inf, max -inf) the lanes of the node's last group past its members.
  void empty_lanes_past_members(const Node& node) {
    const Index used = node.count % kGroup;
    if (used == 0) return;
    Lanes& last = lanes_[static_cast<std::size_t>(node.lanes + node.count / kGroup)];
    for (std::size_t j = 0; j < static_cast<std::size_t>(kAxes); ++j) {
      for (auto l = static_cast<std::size_t>(used); l < static_cast<std::size_t>(kGroup); ++l) {
        last.lo[j][l] = std::numeric_limits<float>::infinity();
        last.hi[j][l] = -std::numeric_limits<float>::infinity();
      }
    }
  }

  static Scalar extent(const Dop& d) {
    return (d.max(0) - d.min(0)) + (d.max(1) - d.min(1)) + (d.max(2) - d.min(2));
  }

  /// Sum of node extents relative to the root's: grows when refit boxes loosen.
  double quality() const {
    double sum = 0;
    for (const Dop& d : dops_) sum += extent(d);
    const double root = extent(dops_[0]);
    return root > 0 ? sum / root : 1;
  }

  // ---- traversal ---------------------------------------------------------------------------
  /// Slots i, j, whose float k-DOPs overlap, are a candidate face pair: they share no corner.
  /// The float test is conservative (`to_float`), and the narrow phase is exact, so the double
  /// k-DOPs are not tested again: that would only drop pairs within a float rounding of
  /// touching, which the narrow phase rejects anyway. The tree's boxes cover the motion (the
  /// hierarchy serves swept queries); contacts are proximity at the current positions, so a
  /// pair whose boxes of the current positions are apart (each inflated by half the pad, like
  /// the swept ones) has none and is not a candidate.
  bool candidate(Index i, Index j) const {
    if (swept_ && now_apart(i, j)) return false;
    const auto si = static_cast<std::size_t>(i), sj = static_cast<std::size_t>(j);
    return !faces_share_vertex(slot_faces_[si], slot_faces_[sj]);
  }
  /// The current-position k-DOPs of slots i and j are apart (swept trees only).
  bool now_apart(Index i, Index j) const {
    return !now_dops_[static_cast<std::size_t>(i)].overlaps(now_dops_[static_cast<std::size_t>(j)]);
  }

  /// The members of leaf n that, with slot i, own no sub-pair (neither owns a vertex, and not
  /// both an edge): left out of a proximity query (`slot_owns_` empty otherwise).
  std::uint64_t idle_with(Index n, Index i) const {
    if (slot_owns_.empty()) return 0;
    // Without a branch: which faces own what is unpredictable.
    const std::uint8_t o = slot_owns_[static_cast<std::size_t>(i)];
    const std::uint64_t owns_vertex = (o & 1u), owns_edge = (o & 2u) >> 1;
    return leaf_no_vertex_[static_cast<std::size_t>(n)] & (owns_vertex - 1) &
           (leaf_no_edge_[static_cast<std::size_t>(n)] | (owns_edge - 1));
  }

  /// The faces of slots i and j, the lesser first.
  FacePair pair_of(Index i, Index j) const {
    const Index f = order_[static_cast<std::size_t>(i)], g = order_[static_cast<std::size_t>(j)];
    return {f < g ? f : g, f < g ? g : f};
  }

  /// The float k-DOP of member i (0-based) of a node, read back from its lanes.
  __attribute__((always_inline)) FloatDop member(const Node& node, Index i) const {
    const Lanes& lanes = lanes_[static_cast<std::size_t>(node.lanes + i / kGroup)];
    const int l = i % kGroup;
    FloatDop f;
    for (std::size_t j = 0; j < static_cast<std::size_t>(kAxes); ++j) {
      f.lo[j] = lanes.lo[j][l];
      f.hi[j] = lanes.hi[j][l];
    }
    return f;
  }

  /// Leaves a and b (node ids); only a's faces that overlap b's k-DOP are tested against b's
  /// faces (adjacent leaves overlap along their shared boundary only).
  CRUMPLE_SIMD_CLONES void emit_leaf_pair(Index ia, Index ib, std::vector<FacePair>& out) const {
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

  /// The members that a leaf's faces' lane tests found: face `slot[k]` against members `first +
  /// l` for the bits l of `members[k]` (not 0), `pairs` bits in all.
  struct Hits {
    std::array<std::uint64_t, 64> members;
    std::array<Index, 64> slot;
    std::size_t queries = 0, pairs = 0;
    void add(Index s, std::uint64_t m) {
      members[queries] = m;
      slot[queries] = s;
      queries += m != 0 ? 1u : 0u;
      pairs += static_cast<std::size_t>(std::popcount(m));
    }
  };
  /// Emits the pairs (slot, first + l) of `hits` for which keep(slot, first + l) holds, in one
  /// flat loop without a branch per pair: a loop over each face's members in turn ended at an
  /// unpredictable count for each face, and whether a pair is kept (shares no vertex) is
  /// unpredictable too (three in five pairs of adjacent leaves share one), so every pair is
  /// written and the next one goes after it or over it.
  template <class Keep>
  __attribute__((always_inline)) void emit_hits(Hits& hits, Index first, const Keep& keep,
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

  /// Bit i set: member `first + i` of the node (child or face slot) is in `only` and may overlap
  /// the k-DOP f (float, conservative; NaN never separates, as in `Kdop::overlaps`). Only the
  /// lane groups with a member in `tested` (which holds `only`) are tested: a caller that
  /// queries several faces against one node passes the members that any of them may want, so
  /// that the groups, and the loop's count, are the same from face to face.
  __attribute__((always_inline)) std::uint64_t overlapping_members(const Node& node, const FloatDop& f,
                                                                   std::uint64_t only = ~std::uint64_t{0},
                                                                   std::uint64_t tested = ~std::uint64_t{0}) const {
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
  __attribute__((always_inline)) std::uint64_t overlapping_node(const Node& node, Index q) const {
    return overlapping_members(node, float_dops_[static_cast<std::size_t>(q)]);
  }

  /// Self-test of node n. With kUnits, the first small node or pair of small nodes reached is a
  /// coherence unit (`unit`); inside a unit, and when coherence is off, kUnits is false.
  template <bool kUnits>
  CRUMPLE_SIMD_CLONES void self(Index n, Walk& w) const {
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
      return;
    }
    for (Index c = node.first; c < node.first + node.count; ++c) self<kUnits>(c, w);
    each_child_pair(node, [&](Index c, Index d) { pair<kUnits>(c, d, w); });
  }

  /// Calls f(c, d) for each pair of children c < d of the inner node whose k-DOPs may overlap:
  /// the pairs that `self` descends to (and that `traverse` splits into tasks).
  template <class F>
  __attribute__((always_inline)) void each_child_pair(const Node& node, const F& f) const {
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
  template <class F>
  __attribute__((always_inline)) void each_descent(Index a, Index b, const F& f) const {
    const Node& na = nodes_[static_cast<std::size_t>(a)];
    const Node& nb = nodes_[static_cast<std::size_t>(b)];
    if (na.leaf || (!nb.leaf && nb.faces > na.faces)) {
      for (std::uint64_t m = overlapping_node(nb, a); m != 0; m &= m - 1) f(a, nb.first + std::countr_zero(m));
    } else {
      for (std::uint64_t m = overlapping_node(na, b); m != 0; m &= m - 1) f(na.first + std::countr_zero(m), b);
    }
  }

  /// Nodes a and b, whose k-DOPs may overlap.
  template <bool kUnits>
  CRUMPLE_SIMD_CLONES void pair(Index a, Index b, Walk& w) const {
    if constexpr (kUnits) {
      if (small_[static_cast<std::size_t>(a)] && small_[static_cast<std::size_t>(b)]) return unit(a, b, w);
    }
    const Node& na = nodes_[static_cast<std::size_t>(a)];
    const Node& nb = nodes_[static_cast<std::size_t>(b)];
    if (na.leaf && nb.leaf) {
      emit_leaf_pair(a, b, w.out);
    } else {
      each_descent(a, b, [&](Index c, Index d) { pair<kUnits>(c, d, w); });
    }
  }

  /// A coherence unit: self(a) when a == b, else pair(a, b). Reuse frames: when the
  /// displacements of the unit's vertices since the refresh frame differ by at most the slack,
  /// the refresh frame's candidates of the unit are emitted (none when it had none); otherwise,
  /// and on other frames, it is traversed, and recorded on a refresh frame.
  CRUMPLE_SIMD_CLONES void unit(Index a, Index b, Walk& w) const {
    const std::uint64_t key = (static_cast<std::uint64_t>(static_cast<std::uint32_t>(std::min(a, b))) << 32) |
                              static_cast<std::uint32_t>(std::max(a, b));
    if (mode_ == Mode::reuse &&
        spread(moved_[static_cast<std::size_t>(a)], moved_[static_cast<std::size_t>(b)]) <= slack_) {
      const auto it = std::lower_bound(units_.begin(), units_.end(), key,
                                       [](const Unit& u, std::uint64_t k) { return u.key < k; });
      if (it != units_.end() && it->key == key) {
        w.out.insert(w.out.end(), unit_pairs_.begin() + static_cast<std::ptrdiff_t>(it->begin),
                     unit_pairs_.begin() + static_cast<std::ptrdiff_t>(it->end));
      }
      ++w.reused;
      return;
    }
    const std::size_t begin = w.out.size();
    if (a == b) {
      self<false>(a, w);
    } else {
      pair<false>(a, b, w);
    }
    ++w.live;
    if (mode_ == Mode::record && w.out.size() > begin) {
      w.units.push_back({key, w.pairs.size(), w.pairs.size() + (w.out.size() - begin)});
      w.pairs.insert(w.pairs.end(), w.out.begin() + static_cast<std::ptrdiff_t>(begin), w.out.end());
    }
  }

  /// Splits the self-traversal of the root into independent tasks (a == b: self(a), else
  /// pair(a, b) of overlapping nodes), then runs them in parallel.
  void traverse(int threads, CandidateBuffer& out, DetectorStats& stats) {
    std::vector<std::array<Index, 2>> tasks{{0, 0}};
    const bool coherent = mode_ != Mode::off;
    // At least 64 tasks a thread, which the threads claim as they go. The splitting is serial
    // (the other threads wait meanwhile), so it stops there. The node pairs are split as the recursion descends (`each_child_pair`,
    // `each_descent`), by float lane tests, cheaper than the nodes' double k-DOPs pair by pair.
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
    std::vector<std::vector<Unit>> units;  // record frames: per chunk, into pairs[chunk]
    std::vector<std::vector<FacePair>> pairs;
    parallel_for_chunks(tasks.size(), threads, 1, [&](std::size_t begin, std::size_t end) {
      Walk w{out.take(), {}, {}};
      for (std::size_t i = begin; i < end; ++i) {
        const auto [a, b] = tasks[i];
        if (a == b) {
          coherent ? self<true>(a, w) : self<false>(a, w);
        } else {
          coherent ? pair<true>(a, b, w) : pair<false>(a, b, w);
        }
        if (!coherent) out.flush_if_full(w.out);  // streaming only; a recording keeps its chunk
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
      cache_valid_ = true;
    }
    if (coherent) {
      stats.set("units_reused", static_cast<double>(reused));
      stats.set("units_traversed", static_cast<double>(live));
    }
  }

  // ---- temporal coherence --------------------------------------------------------------------
  /// Decides this frame's mode and the radius of its refit (larger on a refresh frame).
  void choose_coherence(const FrameInput& in) {
    refit_radius_ = in.radius;
    mode_ = Mode::off;
    if (!params_.coherence || in.intersection_only || in.continuous || (params_.sweep && !in.previous.empty())) {
      cache_valid_ = false;
      return;
    }
    // Displacement boxes take no NaN: a frame with a non-finite coordinate is traversed, and
    // the next finite one records.
    const auto finite = [&] {
      return std::all_of(in.positions.begin(), in.positions.end(), [](const Vec3& p) { return p.allFinite(); });
    };
    if (!cache_valid_ || cache_ref_.size() != in.positions.size()) {
      if (finite()) {
        start_record(in);
      } else {
        cache_valid_ = false;
      }
      return;
    }
    if (cache_wait_ > 0) {  // backing off: traversed, nothing recorded
      --cache_wait_;
      return;
    }
    slack_ = 2 * (cache_radius_ - in.radius);
    if (slack_ > 0 && cache_fresh(in.positions)) {
      if (!finite()) {
        cache_valid_ = false;
        return;
      }
      if (cache_refreshed_) cache_backoff_ = 0;
      cache_refreshed_ = false;
      mode_ = Mode::reuse;
      return;
    }
    // Stale. Right after a refresh the motion per frame is too large for the cache to pay:
    // wait 1, 2, 4, ... 64 frames before recording again.
    if (cache_refreshed_) {
      cache_backoff_ = std::min(64, std::max(1, 2 * cache_backoff_));
      cache_wait_ = cache_backoff_;
      cache_refreshed_ = false;
      return;
    }
    if (finite()) {
      start_record(in);
    } else {
      cache_valid_ = false;
    }
  }

  /// A refresh frame: the k-DOPs are inflated by the slack more, and every unit's candidates
  /// are recorded with the positions.
  void start_record(const FrameInput& in) {
    mode_ = Mode::record;
    cache_radius_ = refit_radius_ = in.radius * (1 + kSlack);
    cache_ref_.assign(in.positions.begin(), in.positions.end());
    units_.clear();
    unit_pairs_.clear();
    cache_valid_ = false;  // until the traversal has recorded every unit
    cache_refreshed_ = true;
  }

  /// Of every 16th leaf, at most a quarter have vertices whose displacements since the refresh
  /// frame differ by more than the slack (else most units would be traversed anyway). Stops as
  /// soon as more than a quarter have (deforming cloth: a quarter of the sample, scattered reads).
  bool cache_fresh(PositionsView x) const {
    const std::size_t samples = (leaf_ids_.size() + 15) / 16;
    std::size_t moved = 0;
    for (std::size_t i = 0; i < leaf_ids_.size(); i += 16) {
      const auto n = static_cast<std::size_t>(leaf_ids_[i]);
      Box m = Box::empty();
      for (std::size_t k = leaf_verts_[n]; k < leaf_verts_[n + 1]; ++k) {
        const auto v = static_cast<std::size_t>(verts_[k]);
        m.grow(x[v] - cache_ref_[v]);
      }
      moved += spread(m, m) <= slack_ ? 0 : 1;
      if (4 * moved > samples) return false;
    }
    return true;
  }

  /// Bound on |(p - p_ref) - (q - q_ref)| for points p, q of the faces of two nodes with these
  /// displacement boxes (a point of a face moves by a convex combination of its corners'
  /// displacements, which lies in the box), with the rounding of x - x_ref (relative to the
  /// displacement) and of the norm covered. Reuse frames have finite positions (checked).
  static Scalar spread(const Box& a, const Box& b) {
    Box u = a;
    u.merge(b);
    Scalar s2 = 0, big = 0;
    for (std::size_t k = 0; k < 3; ++k) {
      s2 += (u.hi[k] - u.lo[k]) * (u.hi[k] - u.lo[k]);
      big = std::max({big, std::abs(u.lo[k]), std::abs(u.hi[k])});
    }
    return std::sqrt(s2) * (1 + 1e-12) + 1e-12 * big;
  }

  const KdopParams& params_;
  // Temporal coherence (proximity frames).
  Mode mode_ = Mode::off;
  Scalar refit_radius_ = 0;  ///< this frame's inflation radius
  bool cache_valid_ = false;  ///< units_ hold a complete refresh frame of the current tree
  bool cache_refreshed_ = false;  ///< the previous frame recorded
  int cache_backoff_ = 0, cache_wait_ = 0;
  Scalar cache_radius_ = 0;  ///< inflation radius of the refresh frame
  Scalar slack_ = 0;         ///< 2 (cache_radius_ - this frame's radius)
  Positions cache_ref_;      ///< positions of the refresh frame
  std::vector<Unit> units_;  ///< the refresh frame's units with candidates, by key
  std::vector<FacePair> unit_pairs_;
  std::vector<Box> moved_;  ///< per node, reuse frames: box of the displacements since the refresh
  std::vector<char> small_;   ///< per node: at most kUnitFaces faces
  std::vector<Index> leaf_ids_;
  std::vector<std::size_t> leaf_verts_;  ///< per node: a leaf's vertices are verts_[n, n + 1)
  std::vector<Index> verts_;
  // The leaves to be, grown at the first build and kept (`grow_patches`).
  std::vector<Index> patch_;  ///< per face, its patch
  std::size_t patches_ = 0;   ///< patch ids are below this
  // Scratch of `build` and `split`, released after the cuts.
  std::vector<Index> component_;          ///< per face, its connected component
  std::vector<Vec3> patch_centroid_;      ///< per patch, mean face centroid
  std::vector<Vec3> component_centroid_;  ///< per component id, mean face centroid
  std::vector<Index> component_faces_;    ///< per component id (all 0 between uses)
  std::vector<Scalar> scratch_;
  std::vector<Node> nodes_;
  std::vector<Dop> dops_;
  std::vector<FloatDop> float_dops_;  ///< per node
  std::vector<Lanes> lanes_;          ///< per node, its members (children or faces) eight to a group
  std::vector<Index> order_;     ///< face of each leaf slot
  std::vector<Face> slot_faces_;  ///< corners of each slot's face (adjacency test locality)
  std::vector<std::uint8_t> slot_owns_;        ///< per slot, FrameInput::owns (proximity queries)
  std::vector<std::uint64_t> leaf_no_vertex_;  ///< per leaf: bit j, member j owns no vertex
  std::vector<std::uint64_t> leaf_no_edge_;    ///< per leaf: bit j, member j owns no edge
  std::vector<std::uint64_t> leaf_adjacent_;  ///< per slot: bit j, member j of its leaf shares a vertex
  std::vector<Dop> now_dops_;     ///< per slot, current positions only, inflated (when swept)
  bool swept_ = false;            ///< this frame's boxes cover the motion
  std::vector<std::array<Index, 2>> levels_;  ///< node range of each depth
  std::vector<Index> level_leaf_faces_;       ///< faces in the leaves of each depth
  double built_quality_ = 0;
  // Normal-cone culling (intersection-only frames).
  bool culling_ = false;
  bool contours_valid_ = false;
  std::vector<Index> contour_offsets_;             ///< per node, into contour_edges_
  std::vector<std::array<Index, 2>> contour_edges_;  ///< directed boundary edges (vertex ids)
  std::vector<char> cullable_;                     ///< per node: consistently oriented, manifold
  std::vector<std::uint32_t> face_masks_, node_masks_;
  PositionsView positions_;
  int threads_ = 0;  ///< of the last update
  mutable std::atomic<long long> culled_{0};
};

}  // namespace

KdopTree::KdopTree(KdopParams params) : params_(params) {
  params_.validate("kdop");  // also for parameters built in code, not through a spec
}

KdopTree::~KdopTree() = default;

void KdopTree::build(const Topology& topology) {
  topo_ = &topology;
  switch (params_.k) {
    case 6:
      tree_ = std::make_unique<DopTree<6>>(params_);
      break;
    case 14:
      tree_ = std::make_unique<DopTree<14>>(params_);
      break;
    case 18:
      tree_ = std::make_unique<DopTree<18>>(params_);
      break;
    default:
      tree_ = std::make_unique<DopTree<26>>(params_);
      break;
  }
}

int KdopTree::levels() const { return tree_ ? tree_->levels() : 0; }

std::vector<Bounds> KdopTree::node_boxes(int depth) const {
  return tree_ ? tree_->boxes(depth) : std::vector<Bounds>{};
}

std::vector<std::vector<Index>> KdopTree::leaf_faces() const {
  return tree_ ? tree_->leaf_faces() : std::vector<std::vector<Index>>{};
}

void KdopTree::update(const FrameInput& in, DetectorStats& stats) {
  CRUMPLE_CHECK(tree_ != nullptr, "kdop: update before build");
  tree_->update(*topo_, in, stats);
}

void KdopTree::self_pairs(CandidateBuffer& out, DetectorStats& stats) { tree_->self_pairs(out, stats); }

}  // namespace crumple
