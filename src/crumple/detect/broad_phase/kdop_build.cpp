// Building the k-DOP hierarchy (kdop_tree_detail.hpp): connected patches of at most `leaf` faces
// (the leaves to be), top-down cuts into `arity` parts at patch or component boundaries, the
// breadth-first node layout, and the per-slot and per-leaf tables the refit and traversal read.
#include <crumple/detect/broad_phase/kdop_tree_detail.hpp>
#include <crumple/detect/narrow_phase.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numeric>
#include <span>
#include <utility>
#include <vector>

namespace crumple::detail {

template <int K>
void DopTree<K>::build(const Topology& topo, PositionsView x, std::span<const std::uint8_t> owns,
                       DetectorStats& stats) {
  const Index nf = topo.num_faces();
  std::vector<Vec3> centroid(static_cast<std::size_t>(nf));
  for (Index f = 0; f < nf; ++f) {
    const Face& t = topo.face(f);
    centroid[static_cast<std::size_t>(f)] = (narrow::at(x, t[0]) + narrow::at(x, t[1]) + narrow::at(x, t[2])) / 3;
  }
  order_.resize(static_cast<std::size_t>(nf));
  std::iota(order_.begin(), order_.end(), 0);
  connected_components(topo, centroid);
  // The patches are grown at the first build only: they are connected pieces of the surface
  // whatever the positions, and growing them is a large part of a build, which a rebuild need
  // not pay again.
  if (patch_.size() != static_cast<std::size_t>(nf)) grow_patches(topo, centroid);
  patch_centroids(centroid);
  cut_nodes(centroid, nf);
  // The component and patch-centroid scratch serves the cuts only (the patches are kept).
  patch_centroid_ = {};
  component_ = {};
  component_centroid_ = {};
  component_faces_ = {};
  scratch_ = {};
  index_slots(topo, owns);
  index_units();
  cache_valid_ = false;
  built_quality_ = 0;  // set by the first refit
  contours_valid_ = false;
  stats.add("rebuilds", 1);
}

/// Connected components (by shared vertices), and each one's mean face centroid: `component_`,
/// `component_centroid_`, and `component_faces_` zeroed, for `component_cut`.
template <int K>
inline void DopTree<K>::connected_components(const Topology& topo, const std::vector<Vec3>& centroid) {
  const Index nf = topo.num_faces();
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

/// The nodes, breadth-first from the root over all `nf` slots: a node of one patch of at most
/// `leaf` faces is a leaf, any other is cut (`split`); every depth is one index range (`levels_`).
template <int K>
inline void DopTree<K>::cut_nodes(const std::vector<Vec3>& centroid, Index nf) {
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
}

/// The lane groups of every node, and per slot and per leaf what the refit and the traversal
/// read: the faces' corners, which faces of a leaf share a vertex, what each face owns.
template <int K>
inline void DopTree<K>::index_slots(const Topology& topo, std::span<const std::uint8_t> owns) {
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
}

/// Per node, whether it fits a coherence unit; per leaf, its sorted vertices (the displacement
/// boxes of the frame-to-frame cache).
template <int K>
inline void DopTree<K>::index_units() {
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
}

/// Cuts the faces into connected patches of at most `leaf` faces (faces sharing a vertex are
/// connected), the leaves to be: each grown from a seed, the first face not yet in a patch in
/// Morton order of the centroids, by adding the face nearest to the seed among those that
/// share a vertex with the patch (of a vertex's first 256 faces); then a patch of fewer than leaf / 4 faces joins the smallest
/// patch it touches that has room. A leaf of one patch stays compact however its surface
/// moves; a leaf of median cuts may hold pieces of surfaces that only pass near each other,
/// and those pieces move apart, loosening the refitted tree. Sets `patch_` and
/// `patches_`; `patch_centroids` then gives the cuts their keys.
template <int K>
inline void DopTree<K>::grow_patches(const Topology& topo, const std::vector<Vec3>& centroid) {
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
template <int K>
inline void DopTree<K>::patch_centroids(const std::vector<Vec3>& centroid) {
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
template <int K>
inline int DopTree<K>::longest_axis(const std::vector<Vec3>& centroid, Index begin, Index end) const {
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
template <int K>
inline void DopTree<K>::group_leaf(const std::vector<Vec3>& centroid, Index begin, Index end) {
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
template <int K>
inline void DopTree<K>::split(const std::vector<Vec3>& centroid, Index begin, Index end, Index parts,
                       std::vector<Index>& cuts) {
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
/// side (separate or stacked bodies; not intertwined rods, which it would cut lengthwise into
/// long, overlapping halves). The axis moving the fewest wins.
/// Returns the cut, with the slots partitioned, or -1 (then the median cut is made).
template <int K>
inline Index DopTree<K>::component_cut(const std::vector<Vec3>& centroid, Index begin, Index end, Index mid,
                                int longest) {
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

#define CRUMPLE_KDOP_INSTANTIATE(K)                                                                 \
  template void DopTree<K>::build(const Topology&, PositionsView, std::span<const std::uint8_t>, DetectorStats&);
CRUMPLE_KDOP_FOR_EACH_K(CRUMPLE_KDOP_INSTANTIATE)
#undef CRUMPLE_KDOP_INSTANTIATE

}  // namespace crumple::detail
