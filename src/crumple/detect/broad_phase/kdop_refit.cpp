// Refitting the k-DOP hierarchy (kdop_tree_detail.hpp): every frame, bottom-up and level by
// level in parallel, each node's k-DOP and its members' float k-DOPs in lane groups; the
// quality metric that triggers a rebuild.
#include <crumple/core/parallel.hpp>
#include <crumple/detect/broad_phase/kdop_tree_detail.hpp>

#include <algorithm>
#include <array>
#include <cstdint>
#include <limits>
#include <span>
#include <vector>

namespace crumple::detail {

namespace {

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

}  // namespace

template <int K>
void DopTree<K>::refit(const FrameInput& in) {
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
template <int K>
inline void DopTree<K>::refit_nodes(std::size_t first, std::size_t last, const FrameInput& in, bool swept,
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
/// loads, which would otherwise stall the loop on each face's first corner.
template <int K>
inline void DopTree<K>::prefetch_corners_ahead(std::span<const Vec3> x, Index s) const {
  if (const auto ahead = static_cast<std::size_t>(s) + 4; ahead < slot_faces_.size()) {
    for (const Index v : slot_faces_[ahead]) __builtin_prefetch(&x[static_cast<std::size_t>(v)]);
  }
}

/// Leaf `node`'s k-DOP, and its faces' float k-DOPs into its lanes (through `faces`, scratch
/// for up to 64 float k-DOPs, except on `refit_leaf18`'s path).
template <int K>
__attribute__((always_inline)) inline typename DopTree<K>::Dop DopTree<K>::refit_leaf_lanes(
    const Node& node, const FrameInput& in, bool swept, Scalar radius, FloatDop* faces) {
  if constexpr (K == 18) {
    if (!swept) return refit_leaf18(node, in.positions, radius);
  }
  const Dop d = refit_leaf(node, in, swept, radius, faces);
  fill_lanes(node, faces);
  return d;
}

/// Leaf `node`'s k-DOP, and its faces' float k-DOPs into `faces` (and their k-DOPs at the
/// current positions into `now_dops_` when swept).
template <int K>
__attribute__((always_inline)) inline typename DopTree<K>::Dop DopTree<K>::refit_leaf(
    const Node& node, const FrameInput& in, bool swept, Scalar radius, FloatDop* faces) {
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

/// `refit_leaf` then `fill_lanes` for the default k = 18 without sweep: the faces' float
/// k-DOPs written straight into the leaf's lanes (no copy through scratch), two slabs per SSE2
/// operation instead of one scalar slab at a time. The same slabs as the generic path, bit for
/// bit (the projections by the same operations as `Kdop::along`, x - y as x + (-y), which IEEE
/// defines it to be; minima and maxima that skip a NaN corner like `extend`; then `inflate`,
/// `merge`, `to_float`).
template <int K>
__attribute__((always_inline)) inline typename DopTree<K>::Dop DopTree<K>::refit_leaf18(
    const Node& node, std::span<const Vec3> x, Scalar radius)
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

template <int K>
inline typename DopTree<K>::FloatDop DopTree<K>::float_dop(const Dop& d) {
  FloatDop f;
  for (int j = 0; j < kAxes; ++j) {
    f.lo[static_cast<std::size_t>(j)] = to_float(d.min(j));
    f.hi[static_cast<std::size_t>(j)] = to_float(d.max(j));
  }
  return f;
}

/// Writes the float k-DOPs of the node's members (faces of a leaf, children otherwise),
/// `members[0, count)`, into its lanes, eight per group; lanes past `count` are empty.
template <int K>
inline void DopTree<K>::fill_lanes(const Node& node, const FloatDop* members) {
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
template <int K>
inline void DopTree<K>::empty_lanes_past_members(const Node& node) {
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

template <int K>
inline Scalar DopTree<K>::extent(const Dop& d) {
  return (d.max(0) - d.min(0)) + (d.max(1) - d.min(1)) + (d.max(2) - d.min(2));
}

/// Sum of node extents relative to the root's: grows when refit boxes loosen.
template <int K>
double DopTree<K>::quality() const {
  double sum = 0;
  for (const Dop& d : dops_) sum += extent(d);
  const double root = extent(dops_[0]);
  return root > 0 ? sum / root : 1;
}

#define CRUMPLE_KDOP_INSTANTIATE(K)                 \
  template void DopTree<K>::refit(const FrameInput&); \
  template double DopTree<K>::quality() const;
CRUMPLE_KDOP_FOR_EACH_K(CRUMPLE_KDOP_INSTANTIATE)
#undef CRUMPLE_KDOP_INSTANTIATE

}  // namespace crumple::detail
