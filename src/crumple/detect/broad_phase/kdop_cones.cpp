// Normal-cone culling of the k-DOP hierarchy's self-tests (kdop_tree.hpp's file comment), for
// intersection-only queries: per node, its faces' common directions and its boundary loop.
#include <crumple/detect/broad_phase/kdop_tree_detail.hpp>
#include <crumple/detect/narrow_phase.hpp>

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstdint>
#include <numbers>
#include <vector>

namespace crumple::detail {

/// The 26 fixed directions: (i, j, k) in {-1, 0, 1}^3 minus the origin, normalised.
template <int K>
inline const std::array<Vec3, 26>& DopTree<K>::directions() {
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
template <int K>
void DopTree<K>::build_contours() {
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
template <int K>
void DopTree<K>::normal_masks(PositionsView x) {
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
template <int K>
bool DopTree<K>::cone_culled(Index n) const {
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

#define CRUMPLE_KDOP_INSTANTIATE(K)                 \
  template void DopTree<K>::build_contours();         \
  template void DopTree<K>::normal_masks(PositionsView); \
  template bool DopTree<K>::cone_culled(Index) const;
CRUMPLE_KDOP_FOR_EACH_K(CRUMPLE_KDOP_INSTANTIATE)
#undef CRUMPLE_KDOP_INSTANTIATE

}  // namespace crumple::detail
