#include <crumple/core/atomic_file.hpp>
#include <crumple/core/error.hpp>
#include <crumple/core/parallel.hpp>
#include <crumple/core/timing.hpp>
#include <crumple/detect/broad_phase/box_tree_detail.hpp>
#include <crumple/detect/broad_phase/broad_phase.hpp>
#include <crumple/detect/broad_phase/hash_grid.hpp>
#include <crumple/detect/broad_phase/kdop_tree.hpp>
#include <crumple/detect/broad_phase/sweep_prune.hpp>
#include <crumple/detect/continuous.hpp>
#include <crumple/detect/continuous_detail.hpp>
#include <crumple/detect/exact/orphans.hpp>
#include <crumple/detect/exact/ownership.hpp>
#include <crumple/detect/exact/stars.hpp>
#include <crumple/detect/scale_detail.hpp>
#include <crumple/geometry/ccd_detail.hpp>
#include <crumple/geometry/distance.hpp>

#include <immintrin.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <bit>
#include <charconv>
#include <chrono>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <limits>
#include <memory>
#include <mutex>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

namespace crumple {

namespace {

/// A face with what it owns (exact/ownership.hpp): VF (v, g) is tested only in the face pair
/// {owner(v), g}, EE (e1, e2) only in {owner(e1), owner(e2)}.
struct OwnedFace {
  std::uint8_t vertex_mask = 0;  // the masks first: FaceFrame keeps them in its first cache line
  std::uint8_t edge_mask = 0;
  /// Side k's corners (k and (k + 1) % 3) in increasing vertex id: the edge's order.
  std::array<std::array<std::uint8_t, 2>, 3> side{};
  Face v;
  std::array<Index, 3> e;
};

/// The float next to the finite `f` towards +∞ (`upward`) or −∞: std::nextafter's answer,
/// from the bits (a library call per face corner was a tenth of filling the face records).
float next_float(float f, bool upward) {
  if (f == 0) return upward ? std::numeric_limits<float>::denorm_min() : -std::numeric_limits<float>::denorm_min();
  const auto bits = std::bit_cast<std::uint32_t>(f);
  // Away from zero, the magnitude's bits grow by one; towards it, they shrink.
  return std::bit_cast<float>((f > 0) == upward ? bits + 1 : bits - 1);
}
/// Rounds toward −∞ (`down`) or +∞ (`up`) to float: a face test on these bounds is never
/// stronger than on the doubles (a lower lo and a higher hi only lower fl(lo_f − hi_g), rounding
/// being monotone), so it too rejects only what the narrow phase's hull filter rejects.
/// Beyond the float range the nearest bound in the right direction is given explicitly (a
/// conversion of an out-of-range double is undefined behaviour).
float down(Scalar x) {
  constexpr Scalar kMax = std::numeric_limits<float>::max();
  if (x > kMax) return std::numeric_limits<float>::max();
  if (x < -kMax) return -std::numeric_limits<float>::infinity();
  float f = static_cast<float>(x);
  if (static_cast<Scalar>(f) > x) f = next_float(f, false);
  return f;
}
float up(Scalar x) {
  constexpr Scalar kMax = std::numeric_limits<float>::max();
  if (x < -kMax) return -std::numeric_limits<float>::max();
  if (x > kMax) return std::numeric_limits<float>::infinity();
  float f = static_cast<float>(x);
  if (static_cast<Scalar>(f) < x) f = next_float(f, true);
  return f;
}

/// The power of two that brings the largest |coordinate| of a pair's points to [1, 2) (1 for
/// all zero): the impact geometry's squared lengths then neither overflow nor underflow (they
/// made barycentric coordinates NaN past ~1e154), and scaling by a power of two is exact, so
/// the barycentric coordinates and normals are those of the unscaled points.
Scalar unit_scale(const geometry::CcdPoints& start, const geometry::CcdPoints& end) {
  Scalar m = 0;
  for (std::size_t i = 0; i < 4; ++i) m = std::max({m, start[i].cwiseAbs().maxCoeff(), end[i].cwiseAbs().maxCoeff()});
  return m > 0 ? std::ldexp(Scalar(1), -std::ilogb(m)) : Scalar(1);
}

/// A face's record for one step, filled once in face order: a candidate reads two records
/// instead of scattered vertex positions. The first cache line holds what the face-level test
/// reads (most candidates stop there); the corners and ids follow.
struct alignas(64) FaceFrame {
  /// The corners' box per time, rounded outwards to float (the lows, then the highs: the face
  /// test takes the differences of the same axis and time two or four at once).
  detail::FaceBoxes box;
  OwnedFace own;                         ///< its masks in the first cache line
  std::array<std::array<Vec3, 3>, 2> x;  ///< x[τ][corner]
};
static_assert(offsetof(FaceFrame, own) + 2 <= 64, "the face test reads one cache line");

/// Floats p[0] and p[1] as two doubles (exact).
__attribute__((always_inline)) inline __m128d widen(const float* p) {
  double two;
  std::memcpy(&two, p, sizeof two);
  return _mm_cvtps_pd(_mm_castpd_ps(_mm_set_sd(two)));
}

/// Bit j = 3 τ + axis set where fl(lo_f − hi_g) > bound for that axis at time τ: the six
/// differences in double two at a time (SSE2, in every x86-64), the same single roundings and
/// comparisons as one at a time (NaN, from ∞ − ∞, compares false).
__attribute__((always_inline)) inline int above_bound(const detail::FaceBoxes& f, const detail::FaceBoxes& g,
                                                      __m128d bound) {
  int above = 0;
  for (int c = 0; c < 3; ++c) {
    const __m128d d = _mm_sub_pd(widen(&f.lo[static_cast<std::size_t>(2 * c)]), widen(&g.hi[static_cast<std::size_t>(2 * c)]));
    above |= _mm_movemask_pd(_mm_cmpgt_pd(d, bound)) << (2 * c);
  }
  return above;
}

/// The slab test of two face records on their float boxes (ccd_slabs_apart's test): apart when
/// on some axis, at t = 0 and at t = 1 alike, one face's low minus the other's high exceeds
/// the bound.
bool boxes_apart(const detail::FaceBoxes& a, const detail::FaceBoxes& b, Scalar bound) {
  const __m128d limit = _mm_set1_pd(bound);
  const int above = above_bound(a, b, limit) | above_bound(b, a, limit) << 6;
  return (above & (above >> 3) & 0b000111'000111) != 0;  // bit j and bit j + 3: the same axis at both times
}

/// boxes_apart as three four-wide double differences (AVX2 only): lanes a.lo − b.hi for
/// j = 0..3, b.lo − a.hi for j = 0..3, then both for j = 4, 5; the same conversions, single
/// roundings and comparisons, so the same answer.
__attribute__((target("avx2"), noinline)) bool boxes_apart_avx2(const detail::FaceBoxes& a,
                                                                const detail::FaceBoxes& b, Scalar bound) {
  // (No lambdas: GCC does not give them the function's target.)
  const __m256d limit = _mm256_set1_pd(bound);
  const __m256d d1 = _mm256_sub_pd(_mm256_cvtps_pd(_mm_loadu_ps(&a.lo[0])), _mm256_cvtps_pd(_mm_loadu_ps(&b.hi[0])));
  const __m256d d2 = _mm256_sub_pd(_mm256_cvtps_pd(_mm_loadu_ps(&b.lo[0])), _mm256_cvtps_pd(_mm_loadu_ps(&a.hi[0])));
  const __m128 lo45 = _mm_loadh_pi(_mm_loadl_pi(_mm_setzero_ps(), reinterpret_cast<const __m64*>(&a.lo[4])),
                                   reinterpret_cast<const __m64*>(&b.lo[4]));
  const __m128 hi45 = _mm_loadh_pi(_mm_loadl_pi(_mm_setzero_ps(), reinterpret_cast<const __m64*>(&b.hi[4])),
                                   reinterpret_cast<const __m64*>(&a.hi[4]));
  const __m256d d3 = _mm256_sub_pd(_mm256_cvtps_pd(lo45), _mm256_cvtps_pd(hi45));
  const int m1 = _mm256_movemask_pd(_mm256_cmp_pd(d1, limit, _CMP_GT_OQ));  // a side, j = 0..3
  const int m2 = _mm256_movemask_pd(_mm256_cmp_pd(d2, limit, _CMP_GT_OQ));  // b side, j = 0..3
  const int m3 = _mm256_movemask_pd(_mm256_cmp_pd(d3, limit, _CMP_GT_OQ));  // a, then b, j = 4, 5
  // Axis k at both times: bits k and k + 3 of a side (j = 3, 4, 5 from m1's bit 3 and m3's 0, 1).
  const int a_side = (m1 & 7) & ((m1 >> 3) | (m3 & 3) << 1);
  const int b_side = (m2 & 7) & ((m2 >> 3) | (m3 >> 2) << 1);
  return (a_side | b_side) != 0;
}

/// A binary tree over faces' boxes at the step's two ends (a face's `CcdSlabs`: its corners'
/// box at t = 0 and at t = 1), queried for the faces whose slabs are not apart from a given
/// face's (`geometry::ccd_slabs_apart`). A node holds, per end, the box of its faces' boxes, so
/// slabs apart from a node's are apart from each of its faces': the answers are exactly the
/// faces that pass the slab test. The same test against the swept box (each face's box over
/// the whole motion) drops far fewer pairs: faces that move together (a falling layer) stay
/// apart at each end while their swept boxes overlap. Built once, refitted as faces move.
class MotionTree {
 public:
  /// The box of some vertices' displacements x¹ − x⁰, and whether one of them is exempt from
  /// the motion bound (`ContinuousQuery::MotionBound`).
  struct MotionBox {
    Vec3 lo, hi;
    bool exempt = false;
  };
  /// Whether every displacement in `a` lies within √reach2 of every one in `b` (neither
  /// exempt): the largest distance between the boxes' points, per axis the larger of the two
  /// far-side differences. (Per coordinate, here and below: Eigen's cwise expressions were
  /// library loops, not inlined.)
  static bool together(const MotionBox& a, const MotionBox& b, Scalar reach2) {
    if (a.exempt || b.exempt) return false;
    Scalar sum = 0;
    for (Eigen::Index k = 0; k < 3; ++k) {
      const Scalar far = std::max(a.hi[k] - b.lo[k], b.hi[k] - a.lo[k]);
      sum += far * far;
    }
    return sum <= reach2;  // NaN: not together
  }
  /// Grows `into` to hold `b`.
  static void merge(MotionBox& into, const MotionBox& b) {
    for (Eigen::Index k = 0; k < 3; ++k) {
      into.lo[k] = std::min(into.lo[k], b.lo[k]);
      into.hi[k] = std::max(into.hi[k], b.hi[k]);
    }
    into.exempt = into.exempt || b.exempt;
  }
  /// Grows `into` to hold the displacement `u`.
  static void grow(MotionBox& into, const Vec3& u) {
    for (Eigen::Index k = 0; k < 3; ++k) {
      into.lo[k] = std::min(into.lo[k], u[k]);
      into.hi[k] = std::max(into.hi[k], u[k]);
    }
  }

  /// Builds over `slabs` (kept by reference; the caller changes them in place and refits).
  void build(std::span<const geometry::CcdSlabs> slabs) {
    slabs_ = slabs;
    items_.resize(slabs.size());
    for (std::size_t i = 0; i < slabs.size(); ++i) items_[i] = static_cast<std::uint32_t>(i);
    nodes_.clear();
    if (!items_.empty()) split(0, items_.size());
  }
  bool built() const { return !nodes_.empty() && items_.size() == slabs_.size(); }

  /// Every node's boxes again cover its faces' current slabs (children first: preorder).
  void refit() {
    for (std::size_t i = nodes_.size(); i-- > 0;) {
      Node& node = nodes_[i];
      if (node.right == 0) {
        node.box = slabs_[items_[node.begin]];
        for (std::uint32_t k = node.begin + 1; k < node.end; ++k) merge(node.box, slabs_[items_[k]]);
      } else {
        node.box = nodes_[node.left].box;
        merge(node.box, nodes_[node.right].box);
      }
    }
  }

  /// Sets every node's motion box from the faces' (`faces[i]`: face i's corners'; kept by
  /// reference until the next call), for `query` with a motion. After `build`.
  void fit_motion(std::span<const MotionBox> faces) {
    face_motion_ = faces;
    node_motion_.resize(nodes_.size());
    for (std::size_t i = nodes_.size(); i-- > 0;) {
      const Node& node = nodes_[i];
      MotionBox& m = node_motion_[i];
      if (node.right == 0) {
        m = faces[items_[node.begin]];
        for (std::uint32_t k = node.begin + 1; k < node.end; ++k) merge(m, faces[items_[k]]);
      } else {
        m = node_motion_[node.left];
        merge(m, node_motion_[node.right]);
      }
    }
  }

  /// Calls hit(i) for every face i whose slabs are not apart from `query`'s by `bound`.
  template <class Hit>
  void query(const geometry::CcdSlabs& query, Scalar bound, const Hit& hit) const {
    if (nodes_.empty()) return;
    std::uint32_t stack[64];  // depth <= log2(n) + 1 (median splits)
    int top = 0;
    stack[top++] = 0;
    while (top > 0) {
      const Node& node = nodes_[stack[--top]];
      if (geometry::ccd_slabs_apart(node.box, query, bound)) continue;
      if (node.right == 0) {
        for (std::uint32_t k = node.begin; k < node.end; ++k) {
          if (!geometry::ccd_slabs_apart(slabs_[items_[k]], query, bound)) hit(items_[k]);
        }
      } else {
        stack[top++] = node.right;
        stack[top++] = node.left;
      }
    }
  }

  /// Calls hit(i, j) once for every unordered pair of distinct faces, one of them flagged in
  /// `flagged` (#faces), whose slabs are not apart by `bound` and, with `motion` (after
  /// `fit_motion`), whose motion boxes are not `together` within √reach2: exactly the pairs
  /// that `query` from each flagged face reports (each once). A dual traversal of the tree with
  /// itself: a pair of nodes is passed over whole when neither holds a flagged face, their slabs
  /// are apart, or their displacements all lie within the reach of each other.
  template <class Hit>
  void self_pairs(std::span<const char> flagged, Scalar bound, bool motion, Scalar reach2, const Hit& hit) {
    if (nodes_.empty()) return;
    node_flag_.resize(nodes_.size());
    for (std::size_t i = nodes_.size(); i-- > 0;) {
      const Node& node = nodes_[i];
      bool any = false;
      if (node.right == 0) {
        for (std::uint32_t k = node.begin; k < node.end; ++k) any = any || flagged[items_[k]] != 0;
      } else {
        any = node_flag_[node.left] || node_flag_[node.right];
      }
      node_flag_[i] = any;
    }
    const auto face_pair = [&](std::uint32_t f, std::uint32_t g) {
      if (!flagged[f] && !flagged[g]) return;
      if (geometry::ccd_slabs_apart(slabs_[f], slabs_[g], bound)) return;
      if (motion && together(face_motion_[f], face_motion_[g], reach2)) return;
      hit(f, g);
    };
    const auto join = [&](const auto& self, std::uint32_t a, std::uint32_t b) -> void {
      if (!node_flag_[a] && !node_flag_[b]) return;
      const Node& na = nodes_[a];
      const Node& nb = nodes_[b];
      if (geometry::ccd_slabs_apart(na.box, nb.box, bound)) return;
      if (motion && together(node_motion_[a], node_motion_[b], reach2)) return;
      if (na.right == 0 && nb.right == 0) {
        for (std::uint32_t i = na.begin; i < na.end; ++i) {
          for (std::uint32_t j = nb.begin; j < nb.end; ++j) face_pair(items_[i], items_[j]);
        }
      } else if (nb.right == 0 || (na.right != 0 && na.end - na.begin >= nb.end - nb.begin)) {
        self(self, na.left, b);
        self(self, na.right, b);
      } else {
        self(self, a, nb.left);
        self(self, a, nb.right);
      }
    };
    const auto within = [&](const auto& self, std::uint32_t a) -> void {
      if (!node_flag_[a]) return;
      if (motion && together(node_motion_[a], node_motion_[a], reach2)) return;
      const Node& na = nodes_[a];
      if (na.right == 0) {
        for (std::uint32_t i = na.begin; i < na.end; ++i) {
          for (std::uint32_t j = i + 1; j < na.end; ++j) face_pair(items_[i], items_[j]);
        }
        return;
      }
      self(self, na.left);
      self(self, na.right);
      join(join, na.left, na.right);
    };
    within(within, 0);
  }

 private:
  static constexpr std::size_t kLeaf = 4;
  struct Node {
    geometry::CcdSlabs box;
    std::uint32_t begin = 0, end = 0;  ///< items [begin, end)
    std::uint32_t left = 0, right = 0;  ///< children (inner nodes); right 0: a leaf
  };
  static void merge(geometry::CcdSlabs& into, const geometry::CcdSlabs& b) {
    for (std::size_t tau = 0; tau < 2; ++tau) {
      into.lo[tau] = into.lo[tau].cwiseMin(b.lo[tau]);
      into.hi[tau] = into.hi[tau].cwiseMax(b.hi[tau]);
    }
  }
  /// The centre of face i's box over both ends along axis a (the split's key).
  Scalar centre(std::uint32_t i, Eigen::Index a) const {
    const geometry::CcdSlabs& b = slabs_[i];
    return std::min(b.lo[0][a], b.lo[1][a]) / 2 + std::max(b.hi[0][a], b.hi[1][a]) / 2;
  }
  /// Adds the node of items [begin, end) and its subtree (median split along the longest
  /// extent of the centres); returns its place. The boxes are set by `refit`.
  std::uint32_t split(std::size_t begin, std::size_t end) {
    const auto at = static_cast<std::uint32_t>(nodes_.size());
    Node node;
    node.box.lo.fill(Vec3::Zero());  // set by `refit`
    node.box.hi.fill(Vec3::Zero());
    node.begin = static_cast<std::uint32_t>(begin);
    node.end = static_cast<std::uint32_t>(end);
    nodes_.push_back(node);
    if (end - begin <= kLeaf) return at;
    Vec3 lo = Vec3::Constant(std::numeric_limits<Scalar>::infinity()), hi = -lo;
    for (std::size_t k = begin; k < end; ++k) {
      for (Eigen::Index a = 0; a < 3; ++a) {
        lo[a] = std::min(lo[a], centre(items_[k], a));
        hi[a] = std::max(hi[a], centre(items_[k], a));
      }
    }
    Eigen::Index axis = 0;
    for (Eigen::Index a = 1; a < 3; ++a) {
      if (hi[a] - lo[a] > hi[axis] - lo[axis]) axis = a;
    }
    const std::size_t mid = begin + (end - begin) / 2;
    std::nth_element(items_.begin() + static_cast<std::ptrdiff_t>(begin), items_.begin() + static_cast<std::ptrdiff_t>(mid),
                     items_.begin() + static_cast<std::ptrdiff_t>(end),
                     [&](std::uint32_t i, std::uint32_t j) { return centre(i, axis) < centre(j, axis); });
    const std::uint32_t left = split(begin, mid);
    const std::uint32_t right = split(mid, end);
    nodes_[at].left = left;
    nodes_[at].right = right;
    return at;
  }

  std::span<const geometry::CcdSlabs> slabs_;
  std::vector<std::uint32_t> items_;
  std::vector<Node> nodes_;
  std::span<const MotionBox> face_motion_;
  std::vector<MotionBox> node_motion_;
  std::vector<char> node_flag_;  ///< `self_pairs`' scratch
};

/// Counters of one chunk of work, summed into the query's stats under a lock.
struct Counts {
  double vf_box_rejected = 0, ee_box_rejected = 0, vf_tests = 0, ee_tests = 0, boxes = 0, face_pairs_apart = 0,
         advance_steps = 0, face_pairs_together = 0, orphans_calm = 0;
  std::array<double, geometry::kCcdOutcomeCount> outcomes{};  ///< narrow-phase tests per `CcdOutcome`
  void add(const Counts& o) {
    for (std::size_t k = 0; k < outcomes.size(); ++k) outcomes[k] += o.outcomes[k];
    vf_box_rejected += o.vf_box_rejected;
    ee_box_rejected += o.ee_box_rejected;
    vf_tests += o.vf_tests;
    ee_tests += o.ee_tests;
    boxes += o.boxes;
    advance_steps += o.advance_steps;
    face_pairs_apart += o.face_pairs_apart;
    face_pairs_together += o.face_pairs_together;
    orphans_calm += o.orphans_calm;
  }
};

/// What the sub-pair tests of one query share.
struct Step {
  const Topology& topo;
  PositionsView x0, x1;
  std::span<const FaceFrame> frames;  ///< per face, its record for this step
  /// `geometry::ccd_hull_bound` of the step's largest coordinate: the slab test rejects only
  /// sub-pairs that the narrow phase's own hull filter rejects (certified apart).
  Scalar hull_bound;
  geometry::CcdOptions narrow;
  /// #V flags of `ContinuousQuery::query_moved`, or null: then every sub-pair is tested.
  const char* moved = nullptr;
  /// Whether the face-level test runs four-wide (`boxes_apart_avx2`).
  bool avx2 = geometry::detail::ccd_has_avx2();
  /// With a `ContinuousQuery::MotionBound`: per vertex its displacement x¹ − x⁰ (as the query
  /// sees them: scaled) and its exempt flag, and the bound's reach squared (scaled); else null.
  const Vec3* motion = nullptr;
  const char* exempt = nullptr;
  Scalar reach2 = 0;
  /// The sweep's motion bound, per face: a face pair whose boxes are `together` is dropped.
  const MotionTree::MotionBox* face_motion = nullptr;
  /// Whether the sub-pair of these four vertices is tested: one of them flagged and, with a
  /// motion bound, one exempt or the sides' relative displacement above the reach. The sides
  /// are a, b, c, d [0, first_b) and [first_b, 4): 1 for VF (the vertex, then the face's
  /// corners), 2 for EE.
  bool wanted(Index a, Index b, Index c, Index d, int first_b) const {
    if (moved == nullptr) return true;  // the sweep: its motion bound acts per face pair and orphan hub
    const auto flagged = [&](Index v) { return moved[static_cast<std::size_t>(v)] != 0; };
    if (!(flagged(a) || flagged(b) || flagged(c) || flagged(d))) return false;
    if (motion == nullptr) return true;
    const std::array<Index, 4> v{a, b, c, d};
    for (const Index i : v) {
      if (exempt[static_cast<std::size_t>(i)]) return true;
    }
    for (int i = 0; i < first_b; ++i) {
      for (int j = first_b; j < 4; ++j) {
        const Vec3 d_ij = motion[static_cast<std::size_t>(v[static_cast<std::size_t>(i)])] -
                          motion[static_cast<std::size_t>(v[static_cast<std::size_t>(j)])];
        if (!(d_ij.squaredNorm() <= reach2)) return true;
      }
    }
    return false;
  }
};

/// The slabs of a face record's three corners.
__attribute__((always_inline)) inline geometry::CcdSlabs slabs_of(const FaceFrame& r) {
  geometry::CcdSlabs s;
  for (std::size_t tau = 0; tau < 2; ++tau) {
    s.lo[tau] = r.x[tau][0].cwiseMin(r.x[tau][1]).cwiseMin(r.x[tau][2]);
    s.hi[tau] = r.x[tau][0].cwiseMax(r.x[tau][1]).cwiseMax(r.x[tau][2]);
  }
  return s;
}

/// The slabs of points `i` and `j` of a face record (an edge).
__attribute__((always_inline)) inline geometry::CcdSlabs slabs_of(const FaceFrame& r, int i, int j) {
  const auto ui = static_cast<std::size_t>(i), uj = static_cast<std::size_t>(j);
  geometry::CcdSlabs s;
  for (std::size_t tau = 0; tau < 2; ++tau) {
    s.lo[tau] = r.x[tau][ui].cwiseMin(r.x[tau][uj]);
    s.hi[tau] = r.x[tau][ui].cwiseMax(r.x[tau][uj]);
  }
  return s;
}

/// The slabs of a query's points `first` .. `first + count - 1`.
__attribute__((always_inline)) inline geometry::CcdSlabs slabs_of(const geometry::CcdPoints& start,
                                                                  const geometry::CcdPoints& end, int first,
                                                                  int count) {
  geometry::CcdSlabs s;
  for (std::size_t tau = 0; tau < 2; ++tau) {
    const geometry::CcdPoints& x = tau == 0 ? start : end;
    s.lo[tau] = s.hi[tau] = x[static_cast<std::size_t>(first)];
    for (int i = first + 1; i < first + count; ++i) {
      s.lo[tau] = s.lo[tau].cwiseMin(x[static_cast<std::size_t>(i)]);
      s.hi[tau] = s.hi[tau].cwiseMax(x[static_cast<std::size_t>(i)]);
    }
  }
  return s;
}

/// The slabs of the step's vertices `ids`, from the positions at t = 0 (`x0`) and t = 1 (`x1`).
template <std::size_t N>
__attribute__((always_inline)) inline geometry::CcdSlabs slabs_of(PositionsView x0, PositionsView x1,
                                                                  const std::array<Index, N>& ids) {
  geometry::CcdSlabs s;
  for (std::size_t tau = 0; tau < 2; ++tau) {
    const PositionsView x = tau == 0 ? x0 : x1;
    s.lo[tau] = s.hi[tau] = x[static_cast<std::size_t>(ids[0])];
    for (std::size_t i = 1; i < N; ++i) {
      s.lo[tau] = s.lo[tau].cwiseMin(x[static_cast<std::size_t>(ids[i])]);
      s.hi[tau] = s.hi[tau].cwiseMax(x[static_cast<std::size_t>(ids[i])]);
    }
  }
  return s;
}

/// Set bits of a 3-bit ownership mask (std::popcount is a library call without -mpopcnt).
int bits(std::uint8_t mask) {
  constexpr std::array<std::uint8_t, 8> kBits{0, 1, 1, 2, 1, 2, 2, 3};
  return kBits[mask & 7u];
}

/// x(t) = p + t (q − p), as the narrow phase's motion.
Vec3 at(const Vec3& p, const Vec3& q, Scalar t) { return p + t * (q - p); }

/// The pair's four points at time t times `unit` (a power of two: exact).
std::array<Vec3, 4> scaled_at(const geometry::CcdPoints& s, const geometry::CcdPoints& e, Scalar t, Scalar unit) {
  return {at(s[0], e[0], t) * unit, at(s[1], e[1], t) * unit, at(s[2], e[2], t) * unit, at(s[3], e[3], t) * unit};
}

/// Lowers an atomic running minimum to `t`.
void lower_to(std::atomic<Scalar>& bound, Scalar t) {
  Scalar current = bound.load(std::memory_order_relaxed);
  while (t < current && !bound.compare_exchange_weak(current, t, std::memory_order_relaxed)) {
  }
}

/// Tests sub-pairs and keeps the impacts (one per thread and chunk). With `earliest`, only
/// the collision-free step is wanted: each test searches only before the running minimum
/// (`CcdOptions::max_time`), hits lower it and no impact is kept.
///
/// Every sub-pair first goes through the slab test (`geometry::ccd_slabs_apart` with the
/// step's bound), which drops only sub-pairs the narrow phase would reject by its hull filter:
/// the impacts are those of the narrow phase on every sub-pair.
///
/// The sub-pairs that pass it wait in a small queue; the narrow phase's coplanarity filter
/// (δ = 0) and separating-direction filter, where most of them end, run on the queue four at a
/// time (geometry/ccd_detail.hpp); the others wait in a second queue per pair type for the rest
/// of the narrow phase (ccd_after_direction, its advancement four sub-pairs in lockstep):
/// together, exactly the narrow phase's results. With `earliest`, a batch of the second queue
/// searches before the running minimum as it was when the batch started (any bound at or above
/// the final minimum gives the same step).
struct Tester {
  const Step& step;
  ImpactSet found;
  Counts counts;
  std::atomic<Scalar>* earliest = nullptr;

  Tester(const Step& s, std::atomic<Scalar>* e) : step(s), earliest(e) {}
  Tester(const Tester&) = delete;
  Tester& operator=(const Tester&) = delete;

  /// A queued sub-pair: VF (i0 = vertex, i1 = face) or EE (i0, i1 = edge ids; a, b = their
  /// vertices, a < b).
  struct Waiting {
    bool face;
    Index i0, i1;
    Edge a, b;
  };
  static constexpr std::size_t kQueue = 64;
  std::array<geometry::detail::CcdQuery, kQueue> queued_points;
  std::array<Waiting, kQueue> queued;
  std::size_t queue_size = 0;

  /// The sub-pairs the batched filters kept, per pair type (0: VF, 1: EE), waiting for the rest
  /// of the narrow phase, whose advancement runs four sub-pairs at a time
  /// (geometry::detail::ccd_after_direction): the more wait, the less often the lanes drain.
  static constexpr std::size_t kKept = 256;
  struct Kept {
    // Not value-initialised (new[] leaves them unset; a tester is built per chunk): only the
    // entries below `size` are ever read, and each is written first.
    std::unique_ptr<geometry::detail::CcdQuery[]> points{new geometry::detail::CcdQuery[kKept]};
    std::unique_ptr<Waiting[]> waiting{new Waiting[kKept]};
    std::size_t size = 0;
  };
  std::array<Kept, 2> kept;
  std::vector<geometry::CcdResult> results;  ///< finish_kept's

  /// Runs the narrow phase on every queued and kept sub-pair (called before the tester's
  /// results are taken).
  void flush() {
    filter_queue();
    finish_kept(kept[0]);
    finish_kept(kept[1]);
  }

  /// Runs the batched filters on the queued sub-pairs and keeps those they do not reject.
  void filter_queue() {
    const std::size_t n = queue_size;
    queue_size = 0;
    if (n == 0 || done()) return;
    const std::span<const geometry::detail::CcdQuery> points{queued_points.data(), n};
    // 1: rejected by the coplanarity filter (δ = 0), 2: by a separating direction.
    std::array<std::uint8_t, kQueue> apart{};
    const bool touching = step.narrow.min_separation == 0;
    if (touching) geometry::detail::ccd_never_coplanar(points, apart.data());
    // The direction filter on the rest, one pair type at a time.
    for (const bool face : {true, false}) {
      std::array<std::uint8_t, kQueue> index{}, result{};
      std::size_t count = 0;
      for (std::size_t i = 0; i < n; ++i) {
        if (apart[i] == 0 && queued[i].face == face) index[count++] = static_cast<std::uint8_t>(i);
      }
      if (count == 0) continue;
      geometry::detail::ccd_separated_by_a_direction(
          face ? geometry::CcdPair::kVertexFace : geometry::CcdPair::kEdgeEdge, points, {index.data(), count},
          step.narrow.min_separation, result.data());
      for (std::size_t j = 0; j < count; ++j) apart[index[j]] = static_cast<std::uint8_t>(2 * result[j]);
    }
    for (std::size_t i = 0; i < n; ++i) {
      const Waiting& w = queued[i];
      ++(w.face ? counts.vf_tests : counts.ee_tests);
      if (apart[i] != 0) {
        ++counts.outcomes[static_cast<std::size_t>(apart[i] == 1 ? geometry::CcdOutcome::kSeparatedCoplanarity
                                                                 : geometry::CcdOutcome::kSeparatedDirection)];
        continue;
      }
      Kept& k = kept[w.face ? 0 : 1];
      if (k.size == kKept) finish_kept(k);
      k.points[k.size] = queued_points[i];
      k.waiting[k.size++] = w;
    }
  }

  /// The rest of the narrow phase (ccd_after_direction) on the kept sub-pairs of one type.
  void finish_kept(Kept& k) {
    const std::size_t n = k.size;
    k.size = 0;
    if (n == 0 || done()) return;
    const geometry::CcdPair pair = k.waiting[0].face ? geometry::CcdPair::kVertexFace : geometry::CcdPair::kEdgeEdge;
    if (results.size() < n) results.resize(n);  // grown as needed: a tester per chunk
    geometry::detail::ccd_after_direction(pair, {k.points.get(), n}, narrow_options(), results.data());
    for (std::size_t i = 0; i < n; ++i) {
      if (!keep(results[i])) continue;
      const Waiting& w = k.waiting[i];
      const geometry::detail::CcdQuery& q = k.points[i];
      if (w.face) {
        record_vertex_face(w.i0, w.i1, q.start, q.end, results[i]);
      } else {
        record_edge_edge(w.i0, w.i1, w.a, w.b, q.start, q.end, results[i]);
      }
    }
  }

  /// True when only the step is wanted and it is already 0: no test can lower it.
  bool done() const { return earliest != nullptr && earliest->load(std::memory_order_relaxed) == 0; }

  geometry::CcdOptions narrow_options() const {
    geometry::CcdOptions o = step.narrow;
    if (earliest != nullptr) o.max_time = earliest->load(std::memory_order_relaxed);
    return o;
  }
  /// Counts a result; true when its impact is wanted.
  bool keep(const geometry::CcdResult& r) {
    counts.boxes += static_cast<double>(r.boxes);
    counts.advance_steps += static_cast<double>(r.advance_steps);
    ++counts.outcomes[static_cast<std::size_t>(r.outcome)];
    if (!r.hit) return false;
    if (earliest == nullptr) return true;
    lower_to(*earliest, r.toi);
    return false;
  }

  /// Queues a sub-pair (the queue flushed first when full); the caller fills its points in the
  /// returned slot (the narrow_* functions' order) before queueing another.
  geometry::detail::CcdQuery& push(const Waiting& w) {
    if (queue_size == kQueue) filter_queue();
    queued[queue_size] = w;
    return queued_points[queue_size++];
  }

  /// Queues vertex v (s[0], e[0]) against face f (s[1..3], e[1..3], corners in order) for the
  /// narrow phase, after the slab test.
  void narrow_vertex_face(Index v, Index f, const geometry::CcdPoints& s, const geometry::CcdPoints& e) {
    if (queue_size == kQueue) filter_queue();
    queued_points[queue_size] = {s, e};
    queued[queue_size++] = {true, v, f, {}, {}};
  }

  /// The impact of a hit `r` of vertex v against face f.
  void record_vertex_face(Index v, Index f, const geometry::CcdPoints& s, const geometry::CcdPoints& e,
                          const geometry::CcdResult& r) {
    VertexFaceImpact impact = vertex_face_impact(s, e, r);
    impact.vertex = v;
    impact.face = f;
    found.vf.push_back(impact);
  }

  /// Queues edges a (s[0..1], e[0..1]) and b (s[2..3], e[2..3]), a < b, each edge's vertices
  /// increasing, for the narrow phase, after the slab test.
  void narrow_edge_edge(Index e0, Index e1, const Edge& a, const Edge& b, const geometry::CcdPoints& s,
                        const geometry::CcdPoints& e) {
    if (queue_size == kQueue) filter_queue();
    queued_points[queue_size] = {s, e};
    queued[queue_size++] = {false, e0, e1, a, b};
  }

  /// The impact of a hit `r` of edges a and b.
  void record_edge_edge(Index e0, Index e1, const Edge& a, const Edge& b, const geometry::CcdPoints& s,
                        const geometry::CcdPoints& e, const geometry::CcdResult& r) {
    EdgeEdgeImpact impact = edge_edge_impact(s, e, r);
    impact.edge0 = e0;
    impact.edge1 = e1;
    impact.a = a;
    impact.b = b;
    found.ee.push_back(impact);
  }

  /// Vertex v against face f, by ids (orphans, stars, isolated vertices).
  void vertex_face(Index v, Index f) {
    if (done()) return;
    const Face& t = step.topo.face(f);
    if (!step.wanted(v, t[0], t[1], t[2], 1)) return;
    const auto s = [&](Index i) { return step.x0[static_cast<std::size_t>(i)]; };
    const auto e = [&](Index i) { return step.x1[static_cast<std::size_t>(i)]; };
    const geometry::CcdPoints start{s(v), s(t[0]), s(t[1]), s(t[2])}, end{e(v), e(t[0]), e(t[1]), e(t[2])};
    if (geometry::ccd_slabs_apart(slabs_of(start, end, 0, 1), slabs_of(start, end, 1, 3), step.hull_bound)) {
      ++counts.vf_box_rejected;
      return;
    }
    narrow_vertex_face(v, f, start, end);
  }

  /// Edges e0 and e1, by ids (orphans, stars).
  void edge_edge(Index e0, Index e1) {
    if (done()) return;
    Edge a = step.topo.edge(e0), b = step.topo.edge(e1);
    if (!step.wanted(a[0], a[1], b[0], b[1], 2)) return;
    if (b < a) {
      std::swap(a, b);
      std::swap(e0, e1);
    }
    const auto s = [&](Index i) { return step.x0[static_cast<std::size_t>(i)]; };
    const auto e = [&](Index i) { return step.x1[static_cast<std::size_t>(i)]; };
    const geometry::CcdPoints start{s(a[0]), s(a[1]), s(b[0]), s(b[1])}, end{e(a[0]), e(a[1]), e(b[0]), e(b[1])};
    if (geometry::ccd_slabs_apart(slabs_of(start, end, 0, 2), slabs_of(start, end, 2, 2), step.hull_bound)) {
      ++counts.ee_box_rejected;
      return;
    }
    narrow_edge_edge(e0, e1, a, b, start, end);
  }

  /// An orphan: vertex v against face f. Its slab test runs first, straight from the
  /// positions (no query is assembled for the most, which it rejects); the slab test does not
  /// depend on the order of the points, so `vertex_face` then gives the same answer.
  void orphan_vertex_face(Index v, Index f) {
    if (done()) return;
    const Face& t = step.topo.face(f);
    if (!step.wanted(v, t[0], t[1], t[2], 1)) return;
    if (geometry::ccd_slabs_apart(slabs_of(step.x0, step.x1, std::array<Index, 1>{v}), slabs_of(step.x0, step.x1, t),
                                  step.hull_bound)) {
      ++counts.vf_box_rejected;
      return;
    }
    vertex_face(v, f);
  }

  /// An orphan edge pair, as `orphan_vertex_face`, with the edges' vertices from the list.
  void orphan_edge_edge(const exact::OrphanEdges& o) {
    if (done()) return;
    if (!step.wanted(o.a[0], o.a[1], o.b[0], o.b[1], 2)) return;
    if (geometry::ccd_slabs_apart(slabs_of(step.x0, step.x1, o.a), slabs_of(step.x0, step.x1, o.b), step.hull_bound)) {
      ++counts.ee_box_rejected;
      return;
    }
    edge_edge(o.e[0], o.e[1]);
  }

  /// Every owned sub-pair of faces fi and gi (sharing no vertex), from their records. The
  /// faces' slabs contain their features' slabs, so faces apart put every sub-pair apart.
  void face_pair(Index fi, Index gi) {
    if (done()) return;
    const FaceFrame& rf = step.frames[static_cast<std::size_t>(fi)];
    const FaceFrame& rg = step.frames[static_cast<std::size_t>(gi)];
    const OwnedFace& f = rf.own;
    const OwnedFace& g = rg.own;
    const int ee_count = bits(f.edge_mask) * bits(g.edge_mask);
    if (step.face_motion != nullptr &&
        MotionTree::together(step.face_motion[static_cast<std::size_t>(fi)], step.face_motion[static_cast<std::size_t>(gi)],
                             step.reach2)) {
      ++counts.face_pairs_together;
      return;  // every sub-pair moves within the reach, none exempt
    }
    if (step.avx2 ? boxes_apart_avx2(rf.box, rg.box, step.hull_bound) : boxes_apart(rf.box, rg.box, step.hull_bound)) {
      counts.vf_box_rejected += bits(f.vertex_mask) + bits(g.vertex_mask);
      counts.ee_box_rejected += ee_count;
      ++counts.face_pairs_apart;
      return;
    }
    if (f.vertex_mask != 0 || g.vertex_mask != 0) {
      const geometry::CcdSlabs fs = slabs_of(rf), gs = slabs_of(rg);
      for (int k = 0; k < 3; ++k) {
        if (f.vertex_mask >> k & 1u) vertex_face(f, rf, k, gi, rg, gs);
        if (g.vertex_mask >> k & 1u) vertex_face(g, rg, k, fi, rf, fs);
      }
    }
    if (ee_count == 0) return;
    std::array<geometry::CcdSlabs, 3> gs;
    for (int j = 0; j < 3; ++j) {
      if (!(g.edge_mask >> j & 1u)) continue;
      const auto& c = g.side[static_cast<std::size_t>(j)];
      gs[static_cast<std::size_t>(j)] = slabs_of(rg, c[0], c[1]);
    }
    for (int i = 0; i < 3; ++i) {
      if (!(f.edge_mask >> i & 1u)) continue;
      const auto& ci = f.side[static_cast<std::size_t>(i)];
      const geometry::CcdSlabs fs = slabs_of(rf, ci[0], ci[1]);
      for (int j = 0; j < 3; ++j) {
        if (!(g.edge_mask >> j & 1u)) continue;
        if (geometry::ccd_slabs_apart(fs, gs[static_cast<std::size_t>(j)], step.hull_bound)) {
          ++counts.ee_box_rejected;
          continue;
        }
        if (done()) return;
        const auto& cj = g.side[static_cast<std::size_t>(j)];
        edge_edge(f, rf, i, ci, g, rg, j, cj);
      }
    }
  }

  /// Corner k of face f (record rf) against face g (record rg, slabs gs).
  __attribute__((always_inline)) void vertex_face(const OwnedFace& f, const FaceFrame& rf, int k, Index gi,
                                                  const FaceFrame& rg, const geometry::CcdSlabs& gs) {
    const auto uk = static_cast<std::size_t>(k);
    if (!step.wanted(f.v[uk], rg.own.v[0], rg.own.v[1], rg.own.v[2], 1)) return;
    geometry::CcdSlabs vs;
    vs.lo = vs.hi = {rf.x[0][uk], rf.x[1][uk]};
    if (geometry::ccd_slabs_apart(vs, gs, step.hull_bound)) {
      ++counts.vf_box_rejected;
      return;
    }
    if (done()) return;
    geometry::detail::CcdQuery& q = push({true, f.v[uk], gi, {}, {}});
    for (std::size_t tau = 0; tau < 2; ++tau) {
      geometry::CcdPoints& to = tau == 0 ? q.start : q.end;
      to[0] = rf.x[tau][uk];
      to[1] = rg.x[tau][0];
      to[2] = rg.x[tau][1];
      to[3] = rg.x[tau][2];
    }
  }

  /// Side i of face f (corners ci, vertex ids increasing) against side j of face g.
  void edge_edge(const OwnedFace& f, const FaceFrame& rf, int i, const std::array<std::uint8_t, 2>& ci,
                 const OwnedFace& g, const FaceFrame& rg, int j, const std::array<std::uint8_t, 2>& cj) {
    if (!step.wanted(f.v[ci[0]], f.v[ci[1]], g.v[cj[0]], g.v[cj[1]], 2)) return;
    Index e0 = f.e[static_cast<std::size_t>(i)], e1 = g.e[static_cast<std::size_t>(j)];
    Edge a{f.v[ci[0]], f.v[ci[1]]}, b{g.v[cj[0]], g.v[cj[1]]};
    const FaceFrame* ra = &rf;
    const FaceFrame* rb = &rg;
    std::array<std::uint8_t, 2> ca = ci, cb = cj;
    if (b < a) {
      std::swap(a, b);
      std::swap(e0, e1);
      std::swap(ra, rb);
      std::swap(ca, cb);
    }
    geometry::detail::CcdQuery& q = push({false, e0, e1, a, b});
    for (std::size_t tau = 0; tau < 2; ++tau) {  // point by point: no temporary array
      geometry::CcdPoints& to = tau == 0 ? q.start : q.end;
      to[0] = ra->x[tau][ca[0]];
      to[1] = ra->x[tau][ca[1]];
      to[2] = rb->x[tau][cb[0]];
      to[3] = rb->x[tau][cb[1]];
    }
  }
};

/// The impact sets' order (`ImpactSet`).
bool vf_less(const VertexFaceImpact& x, const VertexFaceImpact& y) {
  return std::tie(x.vertex, x.face) < std::tie(y.vertex, y.face);
}
bool ee_less(const EdgeEdgeImpact& x, const EdgeEdgeImpact& y) { return std::tie(x.a, x.b) < std::tie(y.a, y.b); }

/// Where a tester's results go: each tester's impacts sorted on its own thread, then appended
/// under the lock as one run; `merge` orders the runs into the final sets
/// (detail::merge_sorted_runs: each impact moved once).
struct Sink {
  std::mutex mutex;
  ImpactSet impacts;
  std::vector<std::size_t> vf_runs, ee_runs;  ///< where each run of `impacts` ends
  Counts counts;
  double narrow_cpu_ms = 0;
  void take(Tester& t, double ms) {
    t.flush();
    // Lambdas, not the function pointers: std::sort then inlines the comparison.
    std::sort(t.found.vf.begin(), t.found.vf.end(), [](const auto& x, const auto& y) { return vf_less(x, y); });
    std::sort(t.found.ee.begin(), t.found.ee.end(), [](const auto& x, const auto& y) { return ee_less(x, y); });
    const std::lock_guard lock(mutex);
    const auto append = [](auto& to, const auto& from, std::vector<std::size_t>& runs) {
      if (from.empty()) return;
      to.insert(to.end(), from.begin(), from.end());
      runs.push_back(to.size());
    };
    append(impacts.vf, t.found.vf, vf_runs);
    append(impacts.ee, t.found.ee, ee_runs);
    counts.add(t.counts);
    narrow_cpu_ms += ms;
  }
  /// The impacts, sorted (keys are unique, so the order is that of a sort of them all).
  void merge() {
    detail::merge_sorted_runs(impacts.vf, vf_runs, [](const auto& x, const auto& y) { return vf_less(x, y); });
    detail::merge_sorted_runs(impacts.ee, ee_runs, [](const auto& x, const auto& y) { return ee_less(x, y); });
  }
};

std::unique_ptr<BroadPhase> make_broad_phase(const MethodSpec& spec) {
  switch (spec.method()) {
    case Method::Kdop:
      return std::make_unique<KdopTree>(KdopParams::from_spec(spec));
    case Method::Hash:
      return std::make_unique<HashGrid>(HashParams::from_spec(spec));
    case Method::Sap:
      return std::make_unique<SweepPrune>(SapParams::from_spec(spec));
    default:
      throw InputError("continuous query: method " + spec.to_string() +
                       " has no broad phase; expected kdop, hash or sap");
  }
}

void put_double(std::ostream& out, double value) {
  char buffer[32];
  const auto result = std::to_chars(buffer, buffer + sizeof buffer, value, std::chars_format::general, 17);
  out.write(buffer, result.ptr - buffer);
}

/// Per vertex, the orphan sub-pairs that hold it (indices into `Orphans::vf` / `ee`, CSR).
struct OrphansOf {
  std::vector<std::size_t> vf_begin, ee_begin;  ///< #V + 1 offsets; empty: not built yet
  std::vector<std::uint32_t> vf, ee;
};

template <class Vertices>
void index_by_vertex(std::size_t nv, std::size_t count, const Vertices& vertices, std::vector<std::size_t>& begin,
                     std::vector<std::uint32_t>& at) {
  begin.assign(nv + 1, 0);
  for (std::size_t i = 0; i < count; ++i) {
    for (const Index v : vertices(i)) ++begin[static_cast<std::size_t>(v) + 1];
  }
  for (std::size_t v = 0; v < nv; ++v) begin[v + 1] += begin[v];
  at.resize(begin[nv]);
  std::vector<std::size_t> next(begin.begin(), begin.end() - 1);
  for (std::size_t i = 0; i < count; ++i) {
    for (const Index v : vertices(i)) at[next[static_cast<std::size_t>(v)]++] = static_cast<std::uint32_t>(i);
  }
}

/// Per orphan (`orphans.vf`, then `orphans.ee`), a vertex whose closed one-ring (itself and the
/// corners of its faces) holds the orphan's four vertices, or -1 when none does. (Every orphan
/// has one: its two features lie in faces sharing a vertex, each face in that vertex's ring.)
std::vector<Index> orphan_hubs(const Topology& topo, const exact::Orphans& orphans) {
  const auto in_ring = [&](Index w, Index x) {
    if (x == w) return true;
    for (const Index f : topo.vertex_faces()[w]) {
      const Face& t = topo.face(f);
      if (t[0] == x || t[1] == x || t[2] == x) return true;
    }
    return false;
  };
  const auto hub = [&](const std::array<Index, 4>& v) -> Index {
    const auto holds_all = [&](Index w) {
      return in_ring(w, v[0]) && in_ring(w, v[1]) && in_ring(w, v[2]) && in_ring(w, v[3]);
    };
    // Likely first: the four themselves (a VF orphan's shared vertex is a corner of its face);
    // then every candidate: a vertex both faces share is v[0] or a corner of a face around it.
    for (const Index w : v) {
      if (holds_all(w)) return w;
    }
    for (const Index f : topo.vertex_faces()[v[0]]) {
      for (const Index w : topo.face(f)) {
        if (holds_all(w)) return w;
      }
    }
    return -1;
  };
  std::vector<Index> out;
  out.reserve(orphans.vf.size() + orphans.ee.size());
  for (const auto& o : orphans.vf) {
    const Face& t = topo.face(o[1]);
    out.push_back(hub({o[0], t[0], t[1], t[2]}));
  }
  for (const auto& o : orphans.ee) out.push_back(hub({o.a[0], o.a[1], o.b[0], o.b[1]}));
  return out;
}

OrphansOf index_orphans(const Topology& topo, const exact::Orphans& orphans) {
  const auto nv = static_cast<std::size_t>(topo.num_vertices());
  OrphansOf out;
  index_by_vertex(nv, orphans.vf.size(), [&](std::size_t i) {
    const Face& t = topo.face(orphans.vf[i][1]);
    return std::array<Index, 4>{orphans.vf[i][0], t[0], t[1], t[2]};
  }, out.vf_begin, out.vf);
  index_by_vertex(nv, orphans.ee.size(), [&](std::size_t i) {
    const exact::OrphanEdges& e = orphans.ee[i];
    return std::array<Index, 4>{e.a[0], e.a[1], e.b[0], e.b[1]};
  }, out.ee_begin, out.ee);
  return out;
}

}  // namespace

VertexFaceImpact vertex_face_impact(const geometry::CcdPoints& s, const geometry::CcdPoints& e,
                                    const geometry::CcdResult& r) {
  VertexFaceImpact impact;
  impact.toi = r.toi;
  impact.outcome = r.outcome;
  // Times `unit`: finite squares at any magnitude (unit_scale).
  const Scalar unit = unit_scale(s, e);
  const auto [p, a, b, c] = scaled_at(s, e, r.toi, unit);
  const geometry::PointTriangleResult q = geometry::point_triangle(p, a, b, c);
  impact.distance = std::sqrt(q.sqr_distance) / unit;
  impact.barycentric = q.barycentric;
  const Vec3 away = p - q.closest;
  if (const Scalar len = away.norm(); len > 0) {
    impact.normal = away / len;
  } else {
    const Vec3 n = (b - a).cross(c - a);
    if (const Scalar n_len = n.norm(); n_len > 0) impact.normal = n / n_len;
  }
  return impact;
}

EdgeEdgeImpact edge_edge_impact(const geometry::CcdPoints& s, const geometry::CcdPoints& e,
                                const geometry::CcdResult& r) {
  EdgeEdgeImpact impact;
  impact.toi = r.toi;
  impact.outcome = r.outcome;
  const Scalar unit = unit_scale(s, e);
  const auto [p0, p1, q0, q1] = scaled_at(s, e, r.toi, unit);
  const geometry::SegmentSegmentResult q = geometry::segment_segment(p0, p1, q0, q1);
  impact.distance = std::sqrt(q.sqr_distance) / unit;
  impact.s = q.s;
  impact.t = q.t;
  const Vec3 across = q.closest1 - q.closest0;
  if (const Scalar len = across.norm(); len > 0) {
    impact.normal = across / len;
  } else {
    const Vec3 n = (p1 - p0).cross(q1 - q0);
    if (const Scalar n_len = n.norm(); n_len > 0) impact.normal = n / n_len;
  }
  return impact;
}

struct ContinuousQuery::State {
  OrphansOf orphans_of;  ///< built at the first `query_moved`
  std::unique_ptr<BroadPhase> broad;
  CandidateBuffer candidates;
  exact::FeatureOwnership own;
  exact::Orphans orphans;
  std::vector<std::uint8_t> face_owns;
  std::vector<OwnedFace> faces;
  std::vector<Box> vertex_box;
  std::vector<FaceFrame> frames;  // 64-byte aligned elements (C++17 aligned new)
  int exponent = 0;       ///< the last step's scale exponent (detect/scale_detail.hpp)
  Positions x0, x1;       ///< the step's positions times 2^exponent, when it is not 0
  /// The restricted queries' tree of every face's slabs (`query_moved`): `face_slabs[f]` is
  /// face f's for the motion `face_x0` → `face_x1` (as the query sees them: scaled); built at
  /// the first restricted query, refitted at the next ones where vertices moved.
  std::vector<geometry::CcdSlabs> face_slabs;
  MotionTree face_tree;
  Positions face_x0, face_x1;
  std::vector<char> face_dirty;
  std::vector<Index> dirty;
  /// A restricted query's motion bound (`MotionBound`): per vertex its displacement (scaled)
  /// and per face its corners' motion box.
  Positions motion;
  std::vector<MotionTree::MotionBox> face_motion;
  /// Per orphan (VF, then EE), a vertex whose closed one-ring holds its four vertices, or -1
  /// (built at the first sweep with a motion bound); per vertex, whether its closed one-ring
  /// moves within the bound's reach with no exempt vertex (each such sweep).
  std::vector<Index> orphan_hub;
  std::vector<char> calm;
  std::vector<std::uint32_t> orphan_seen;  ///< per orphan, the restricted query that gathered it
  std::uint32_t orphan_stamp = 0;
};

namespace {

/// The step as the query computes it: the positions, and δ, times 2^k for the k of the
/// detectors (detect/scale_detail.hpp), so that far from unit magnitudes the err terms of the
/// narrow phase stay relative and its squares finite; the distances of its impacts are scaled
/// back by 2^-k. The broad phase starts over when k changes (its refit keeps coordinates).
struct ScaledStep {
  PositionsView x0, x1;
  Scalar delta;
  geometry::CcdOptions narrow;
  int exponent;
};
ScaledStep scale_step(ContinuousQuery::State& s, const Topology& topo, const ContinuousOptions& options,
                      PositionsView previous, PositionsView current) {
  const int threads = options.threads;
  const int k = detail::detection_exponent(
      std::max(detail::finite_magnitude(previous, threads), detail::finite_magnitude(current, threads)));
  if (k != s.exponent) s.broad->build(topo);
  s.exponent = k;
  ScaledStep out{previous, current, options.min_separation, options.narrow, k};
  if (k != 0) {
    detail::scale_positions(previous, k, s.x0, threads, "continuous query: previous positions");
    detail::scale_positions(current, k, s.x1, threads, "continuous query: current positions");
    out.x0 = s.x0;
    out.x1 = s.x1;
    out.delta = detail::scaled_thickness(options.min_separation, k);
    out.narrow.min_separation = out.delta;
  }
  return out;
}

}  // namespace

ContinuousQuery::ContinuousQuery(std::shared_ptr<const Topology> topology, ContinuousOptions options)
    : topology_(std::move(topology)), options_(std::move(options)), state_(std::make_unique<State>()) {
  CRUMPLE_CHECK(topology_ != nullptr, "ContinuousQuery: null topology");
  const Scalar delta = options_.min_separation;
  if (!(std::isfinite(delta) && delta >= 0)) {
    throw InputError("continuous query: the minimum separation must be a finite number >= 0, got " +
                     std::to_string(delta));
  }
  const geometry::CcdOptions& n = options_.narrow;
  if (!(n.time_tolerance > 0 && n.distance_tolerance >= 0 && n.separation_tolerance >= 0 && n.max_boxes >= 1 &&
        n.max_advance_steps >= 0 && std::isfinite(n.distance_tolerance) && std::isfinite(n.separation_tolerance))) {
    throw InputError(
        "continuous query: narrow-phase options need time_tolerance > 0, finite distance and separation "
        "tolerances >= 0, max_boxes >= 1 and max_advance_steps >= 0");
  }
  options_.narrow.min_separation = delta;
  State& s = *state_;
  s.broad = make_broad_phase(options_.method);
  const Topology& topo = *topology_;
  s.own = exact::own_features(topo);
  const exact::FeatureOwnership& own = s.own;
  s.orphans = exact::list_orphans(topo, own);
  s.face_owns = own.face_owns();
  s.faces.resize(static_cast<std::size_t>(topo.num_faces()));
  for (Index f = 0; f < topo.num_faces(); ++f) {
    OwnedFace& of = s.faces[static_cast<std::size_t>(f)];
    of.v = topo.face(f);
    of.e = topo.face_edges(f);
    for (std::size_t k = 0; k < 3; ++k) {
      const auto k1 = static_cast<std::uint8_t>((k + 1) % 3);
      const bool increasing = of.v[k] < of.v[k1];
      of.side[k] = {increasing ? static_cast<std::uint8_t>(k) : k1, increasing ? k1 : static_cast<std::uint8_t>(k)};
    }
    of.vertex_mask = own.vertex_mask[static_cast<std::size_t>(f)];
    of.edge_mask = own.edge_mask[static_cast<std::size_t>(f)];
  }
  s.broad->build(topo);
}

ContinuousQuery::~ContinuousQuery() = default;

namespace {

/// Checks the sizes and finiteness of a step's positions and fills the vertex boxes; returns
/// the largest coordinate magnitude.
Scalar prepare_step(const Topology& topo, PositionsView x0, PositionsView x1, int threads,
                    std::vector<Box>& vertex_box) {
  const auto nv = static_cast<std::size_t>(topo.num_vertices());
  for (const auto& [x, name] : {std::pair{x0, "previous"}, std::pair{x1, "current"}}) {
    if (x.size() != nv) {
      throw InputError(std::string("continuous query: ") + name + " positions have " + std::to_string(x.size()) +
                       " entries for " + std::to_string(nv) + " vertices");
    }
  }
  vertex_box.resize(nv);
  std::mutex mutex;
  Scalar magnitude = 0;
  std::size_t bad = nv;  // the first vertex with a non-finite coordinate
  parallel_for_chunks(nv, threads, 4096, [&](std::size_t begin, std::size_t end) {
    Scalar m = 0;
    std::size_t first_bad = nv;
    for (std::size_t v = begin; v < end; ++v) {
      if (!(x0[v].allFinite() && x1[v].allFinite())) {
        first_bad = std::min(first_bad, v);
        continue;
      }
      Box b = Box::empty();
      b.grow(x0[v]);
      b.grow(x1[v]);
      vertex_box[v] = b;
      m = std::max({m, x0[v].cwiseAbs().maxCoeff(), x1[v].cwiseAbs().maxCoeff()});
    }
    const std::lock_guard lock(mutex);
    magnitude = std::max(magnitude, m);
    bad = std::min(bad, first_bad);
  });
  if (bad < nv) {
    const char* which = x0[bad].allFinite() ? "current" : "previous";
    throw InputError(std::string("continuous query: vertex ") + std::to_string(bad) + " has a non-finite coordinate in the " +
                     which + " positions");
  }
  return magnitude;
}

}  // namespace

std::size_t ContinuousQuery::count_candidates(PositionsView given_previous, PositionsView given_current) {
  State& s = *state_;
  const Topology& topo = *topology_;
  stats_.clear();
  const ScaledStep scaled = scale_step(s, topo, options_, given_previous, given_current);
  const Scalar magnitude = prepare_step(topo, scaled.x0, scaled.x1, options_.threads, s.vertex_box);
  const Scalar reach = scaled.delta * (1 + 1e-6) + 1e-9 * magnitude;
  const auto t0 = std::chrono::steady_clock::now();
  FrameInput in{scaled.x0, scaled.x1, reach / 2, options_.threads, false, s.face_owns, true};
  s.broad->update(in, stats_);
  stats_.set("update_ms", ms_since(t0));
  const auto t1 = std::chrono::steady_clock::now();
  const std::size_t n = stream_self_pairs(*s.broad, s.candidates, stats_, [](std::span<const FacePair>) {}).candidates;
  stats_.set("stream_ms", ms_since(t1));
  stats_.set("candidates", static_cast<double>(n));
  return n;
}

void ContinuousQuery::query(PositionsView previous, PositionsView current, ImpactSet& out) {
  run(previous, current, {}, out, nullptr);
}

void ContinuousQuery::query(PositionsView previous, PositionsView current, const MotionBound& bound,
                            ImpactSet& out) {
  const auto nv = static_cast<std::size_t>(topology_->num_vertices());
  if (bound.exempt.size() != nv) {
    out.clear();
    throw InputError("continuous query: " + std::to_string(bound.exempt.size()) + " exempt flags for " +
                     std::to_string(nv) + " vertices");
  }
  if (!(bound.reach >= 0 && std::isfinite(bound.reach))) {
    out.clear();
    throw InputError("continuous query: the motion bound's reach must be finite and >= 0");
  }
  run(previous, current, {}, out, nullptr, &bound);
}

void ContinuousQuery::query_moved(PositionsView previous, PositionsView current, std::span<const char> moved,
                                  ImpactSet& out) {
  const auto nv = static_cast<std::size_t>(topology_->num_vertices());
  if (moved.size() != nv) {
    out.clear();
    throw InputError("continuous query: " + std::to_string(moved.size()) + " moved flags for " + std::to_string(nv) +
                     " vertices");
  }
  // Empty means "all" to `run`: a mesh with no vertex has no impact either way.
  run(previous, current, moved, out, nullptr);
}

void ContinuousQuery::query_moved(PositionsView previous, PositionsView current, std::span<const char> moved,
                                  const MotionBound& bound, ImpactSet& out) {
  const auto nv = static_cast<std::size_t>(topology_->num_vertices());
  if (moved.size() != nv || bound.exempt.size() != nv) {
    out.clear();
    throw InputError("continuous query: " + std::to_string(moved.size()) + " moved and " +
                     std::to_string(bound.exempt.size()) + " exempt flags for " + std::to_string(nv) + " vertices");
  }
  if (!(bound.reach >= 0 && std::isfinite(bound.reach))) {
    out.clear();
    throw InputError("continuous query: the motion bound's reach must be finite and >= 0");
  }
  run(previous, current, moved, out, nullptr, &bound);
}

void ContinuousQuery::update_moved(PositionsView previous, PositionsView current, std::span<const char> moved,
                                   ImpactSet& impacts) {
  try {
    query_moved(previous, current, moved, fresh_);
  } catch (...) {
    impacts.clear();
    throw;
  }
  const Topology& topo = *topology_;
  const auto flagged = [&](Index u) { return moved[static_cast<std::size_t>(u)] != 0; };
  std::erase_if(impacts.vf, [&](const VertexFaceImpact& i) {
    const Face& t = topo.face(i.face);
    return flagged(i.vertex) || flagged(t[0]) || flagged(t[1]) || flagged(t[2]);
  });
  std::erase_if(impacts.ee, [&](const EdgeEdgeImpact& i) {
    return flagged(i.a[0]) || flagged(i.a[1]) || flagged(i.b[0]) || flagged(i.b[1]);
  });
  // Both sorted and disjoint (a kept impact has no flagged vertex, a fresh one has one).
  const auto merge_into = [](auto& kept, const auto& added, const auto& less) {
    const auto middle = static_cast<std::ptrdiff_t>(kept.size());
    kept.insert(kept.end(), added.begin(), added.end());
    std::inplace_merge(kept.begin(), kept.begin() + middle, kept.end(), less);
  };
  merge_into(impacts.vf, fresh_.vf, vf_less);
  merge_into(impacts.ee, fresh_.ee, ee_less);
}

Scalar ContinuousQuery::collision_free_step(PositionsView previous, PositionsView current) {
  std::atomic<Scalar> earliest{1};
  ImpactSet none;
  run(previous, current, {}, none, &earliest);
  stats_.set("collision_free_step", earliest.load());
  return earliest.load();
}

void ContinuousQuery::run(PositionsView given_previous, PositionsView given_current, std::span<const char> moved,
                          ImpactSet& out, std::atomic<Scalar>* earliest, const MotionBound* bound) {
  out.clear();
  State& s = *state_;
  const Topology& topo = *topology_;
  const int threads = options_.threads;
  stats_.clear();
  const auto start = std::chrono::steady_clock::now();
  const ScaledStep scaled = scale_step(s, topo, options_, given_previous, given_current);
  const PositionsView previous = scaled.x0, current = scaled.x1;
  const Scalar magnitude = prepare_step(topo, previous, current, threads, s.vertex_box);
  // Two features within δ at some t lie in faces whose swept boxes, each grown by δ/2, meet;
  // the margin covers the rounding of every box bound (docs/ccd.md, broad phase).
  const Scalar reach = scaled.delta * (1 + 1e-6) + 1e-9 * magnitude;
  s.frames.resize(static_cast<std::size_t>(topo.num_faces()));
  const auto fill_frame = [&](std::size_t f) {
    FaceFrame& r = s.frames[f];
    r.own = s.faces[f];
    for (std::size_t k = 0; k < 3; ++k) {
      r.x[0][k] = previous[static_cast<std::size_t>(r.own.v[k])];
      r.x[1][k] = current[static_cast<std::size_t>(r.own.v[k])];
    }
    for (std::size_t tau = 0; tau < 2; ++tau) {
      const Vec3 lo = r.x[tau][0].cwiseMin(r.x[tau][1]).cwiseMin(r.x[tau][2]);
      const Vec3 hi = r.x[tau][0].cwiseMax(r.x[tau][1]).cwiseMax(r.x[tau][2]);
      for (std::size_t k = 0; k < 3; ++k) {
        r.box.lo[3 * tau + k] = down(lo[static_cast<Eigen::Index>(k)]);
        r.box.hi[3 * tau + k] = up(hi[static_cast<Eigen::Index>(k)]);
      }
    }
  };
  if (moved.empty()) {  // a restricted query fills the records of the faces it tests only
    parallel_for_chunks(s.frames.size(), threads, 4096, [&](std::size_t begin, std::size_t end) {
      for (std::size_t f = begin; f < end; ++f) fill_frame(f);
    });
  }
  Step bounded{topo,
               previous,
               current,
               s.frames,
               geometry::ccd_hull_bound(magnitude, scaled.delta),
               scaled.narrow,
               moved.empty() ? nullptr : moved.data()};
  if (bound != nullptr) {
    // The displacements as the query sees them (scaled by 2^k: exact, as is the reach's scaling).
    const auto nv = static_cast<std::size_t>(topo.num_vertices());
    s.motion.resize(nv);
    for (std::size_t v = 0; v < nv; ++v) s.motion[v] = current[v] - previous[v];
    const Scalar r = std::ldexp(bound->reach, scaled.exponent);
    bounded.motion = s.motion.data();
    bounded.exempt = bound->exempt.data();
    bounded.reach2 = r * r;
    // Every face's motion box: its corners' displacements, exempt with one of them.
    const auto nf = static_cast<std::size_t>(topo.num_faces());
    s.face_motion.resize(nf);
    for (std::size_t f = 0; f < nf; ++f) {
      MotionTree::MotionBox& m = s.face_motion[f];
      const Face& t = topo.face(static_cast<Index>(f));
      m.lo = m.hi = s.motion[static_cast<std::size_t>(t[0])];
      m.exempt = bound->exempt[static_cast<std::size_t>(t[0])] != 0;
      for (std::size_t k = 1; k < 3; ++k) {
        const auto v = static_cast<std::size_t>(t[k]);
        MotionTree::grow(m, s.motion[v]);
        m.exempt = m.exempt || bound->exempt[v] != 0;
      }
    }
    if (moved.empty()) bounded.face_motion = s.face_motion.data();
  }
  const Step& step = bounded;
  Sink sink;
  const Scalar half = reach / 2;
  const auto swept_box = [&](Index u) { return s.vertex_box[static_cast<std::size_t>(u)]; };
  const auto face_box = [&](Index f) {
    Box b = Box::empty();
    for (const Index u : topo.face(f)) b.merge(swept_box(u));
    b.inflate(half);
    return b;
  };
  const auto flagged = [&](Index u) { return moved[static_cast<std::size_t>(u)] != 0; };

  if (step.moved != nullptr) {
    // One-sided: a sub-pair with a flagged vertex lies in the face pair that owns it, and one
    // face of that pair holds the flagged vertex (the vertex of a VF pair is a corner of its
    // owner; an edge, of its owner). So the faces touching a flagged vertex (their swept boxes
    // in a tree) against every face's swept box, grown as in the broad phase, find every such
    // face pair whose features may come within δ; pairs sharing a vertex are the orphans'.
    const auto t1 = std::chrono::steady_clock::now();
    const auto nf = static_cast<std::size_t>(topo.num_faces());
    std::vector<char> face_moved(nf, 0);
    std::vector<Index> touched;
    for (std::size_t f = 0; f < nf; ++f) {
      const Face& t = topo.face(static_cast<Index>(f));
      if (!(flagged(t[0]) || flagged(t[1]) || flagged(t[2]))) continue;
      face_moved[f] = 1;
      touched.push_back(static_cast<Index>(f));
    }
    // The tree of every face's slabs for this step, built once (its node order follows the
    // first restricted query's motion) and refitted since, as the broad phase's own tree: the
    // slabs of the faces around a vertex whose x⁰ or x¹ changed (bit for bit) since the last
    // restricted query are recomputed (all of them when most faces changed) and the nodes
    // refitted, so each face's slabs are exactly this step's.
    const auto nv = static_cast<std::size_t>(topo.num_vertices());
    const auto slabs_of_face = [&](std::size_t f) {
      s.face_slabs[f] = slabs_of(previous, current, topo.face(static_cast<Index>(f)));
    };
    const auto all_slabs = [&] {
      parallel_for_chunks(nf, threads, 4096, [&](std::size_t begin, std::size_t end) {
        for (std::size_t f = begin; f < end; ++f) slabs_of_face(f);
      });
      s.face_x0.assign(previous.begin(), previous.end());
      s.face_x1.assign(current.begin(), current.end());
    };
    std::size_t refitted = nf;
    const bool build = !s.face_tree.built() || s.face_slabs.size() != nf || s.face_x0.size() != nv;
    if (touched.empty()) {  // nothing to query: the next query catches the tree up
      refitted = 0;
    } else if (build) {
      s.face_slabs.resize(nf);
      all_slabs();
      s.face_tree.build(s.face_slabs);
    } else {
      s.face_dirty.resize(nf, 0);
      s.dirty.clear();
      for (std::size_t v = 0; v < nv && 4 * s.dirty.size() <= nf; ++v) {
        if (std::memcmp(previous[v].data(), s.face_x0[v].data(), sizeof(Vec3)) == 0 &&
            std::memcmp(current[v].data(), s.face_x1[v].data(), sizeof(Vec3)) == 0) {
          continue;
        }
        s.face_x0[v] = previous[v];
        s.face_x1[v] = current[v];
        for (const Index f : topo.vertex_faces()[static_cast<Index>(v)]) {
          if (!s.face_dirty[static_cast<std::size_t>(f)]) {
            s.face_dirty[static_cast<std::size_t>(f)] = 1;
            s.dirty.push_back(f);
          }
        }
      }
      for (const Index f : s.dirty) s.face_dirty[static_cast<std::size_t>(f)] = 0;
      if (4 * s.dirty.size() > nf) {  // the loop stopped early; `all_slabs` sets face_x0/x1
        all_slabs();
      } else {
        for (const Index f : s.dirty) slabs_of_face(static_cast<std::size_t>(f));
        refitted = s.dirty.size();
      }
    }
    if (refitted > 0) s.face_tree.refit();
    const bool by_motion = step.motion != nullptr && !touched.empty();
    if (by_motion) s.face_tree.fit_motion(s.face_motion);  // the nodes' motion boxes
    // Each touching face queries the tree: the face pairs with a touching face whose swept
    // boxes meet, as in the broad phase, each unordered pair once (a pair of two touching
    // faces is found from both), less those whose slabs are apart: every sub-pair's slabs then
    // are (a feature's slabs lie in its face's), which the narrow phase rejects by its hull
    // filter, so leaving them out changes no impact. The slab test is the tree's: faces that
    // move together (a falling layer) stay apart at each end while their swept boxes meet.
    const auto swept = [&](const geometry::CcdSlabs& b) {  // `face_box`, bit for bit
      Box box;
      for (std::size_t k = 0; k < 3; ++k) {
        const auto a = static_cast<Eigen::Index>(k);
        box.lo[k] = std::min(b.lo[0][a], b.lo[1][a]) - half;
        box.hi[k] = std::max(b.hi[0][a], b.hi[1][a]) + half;
      }
      return box;
    };
    std::vector<FacePair> pairs;
    const auto keep = [&](Index f, Index g) {  // as the broad phase: swept boxes meet, no shared vertex
      if (!swept(s.face_slabs[static_cast<std::size_t>(f)]).overlaps(swept(s.face_slabs[static_cast<std::size_t>(g)]))) {
        return;
      }
      const Face& tf = topo.face(f);
      for (const Index u : topo.face(g)) {
        if (u == tf[0] || u == tf[1] || u == tf[2]) return;
      }
      pairs.push_back({f, g});
    };
    if (by_motion) {
      // With a motion bound, a dual traversal of the tree with itself (`self_pairs`), which
      // passes over whole node pairs whose corners move within the reach of each other: every
      // sub-pair of such faces has a relative displacement within it and no exempt vertex, so
      // `wanted` would drop it. (Per-face queries pruned the same way cost more than the sweep:
      // each of the many fast faces descended the tree to its own neighbourhood.)
      s.face_tree.self_pairs(face_moved, step.hull_bound, true, step.reach2, [&](std::uint32_t f, std::uint32_t g) {
        keep(static_cast<Index>(f), static_cast<Index>(g));
      });
    } else {
      std::mutex pairs_mutex;
      parallel_for_chunks(touched.size(), threads, 256, [&](std::size_t begin, std::size_t end) {
        std::vector<FacePair> found;
        for (std::size_t k = begin; k < end; ++k) {
          const Index f = touched[k];
          const Face& tf = topo.face(f);
          const Box box = swept(s.face_slabs[static_cast<std::size_t>(f)]);
          s.face_tree.query(s.face_slabs[static_cast<std::size_t>(f)], step.hull_bound, [&](std::uint32_t gu) {
            const auto g = static_cast<Index>(gu);
            if (g == f || (face_moved[gu] && g < f) || !box.overlaps(swept(s.face_slabs[gu]))) return;
            for (const Index u : topo.face(g)) {
              if (u == tf[0] || u == tf[1] || u == tf[2]) return;
            }
            found.push_back({f, g});
          });
        }
        const std::lock_guard lock(pairs_mutex);
        pairs.insert(pairs.end(), found.begin(), found.end());
      });
    }
    stats_.set("face_tree_built", build && !touched.empty() ? 1 : 0);
    stats_.set("face_slabs_refitted", static_cast<double>(refitted));
    // The records of the faces of these pairs only.
    std::vector<Index> needed;
    for (const FacePair& p : pairs) {
      for (const Index f : p) {
        if (face_moved[static_cast<std::size_t>(f)] != 2) {
          face_moved[static_cast<std::size_t>(f)] = 2;
          needed.push_back(f);
        }
      }
    }
    parallel_for_chunks(needed.size(), threads, 1024, [&](std::size_t begin, std::size_t end) {
      for (std::size_t i = begin; i < end; ++i) fill_frame(static_cast<std::size_t>(needed[i]));
    });
    parallel_for_chunks(pairs.size(), threads, 1024, [&](std::size_t begin, std::size_t end) {
      const auto c0 = std::chrono::steady_clock::now();
      Tester tester(step, earliest);
      for (std::size_t i = begin; i < end; ++i) tester.face_pair(pairs[i][0], pairs[i][1]);
      tester.flush();
      sink.take(tester, ms_since(c0));
    });
    stats_.set("moved_faces", static_cast<double>(touched.size()));
    stats_.set("candidates", static_cast<double>(pairs.size()));
    stats_.set("stream_ms", ms_since(t1));
    stats_.set("narrow_cpu_ms", sink.narrow_cpu_ms);
  } else {
    // Broad phase, its candidates streamed to the narrow phase on its threads.
    const auto t0 = std::chrono::steady_clock::now();
    FrameInput in{previous, current, reach / 2, threads, false, s.face_owns, true};
    s.broad->update(in, stats_);
    stats_.set("update_ms", ms_since(t0));
    const auto t1 = std::chrono::steady_clock::now();
    const StreamedPairs streamed = stream_self_pairs(*s.broad, s.candidates, stats_, [&](std::span<const FacePair> chunk) {
      const auto c0 = std::chrono::steady_clock::now();
      Tester tester(step, earliest);
      // The records of a pair a few pairs ahead are fetched while this one is tested (the face
      // ids of a chunk are scattered: the loop is otherwise bound by memory latency).
      constexpr std::size_t kAhead = 16;
      for (std::size_t i = 0; i < chunk.size(); ++i) {
        if (i + kAhead < chunk.size()) {
          for (const Index f : chunk[i + kAhead]) {
            const auto* line = reinterpret_cast<const char*>(&s.frames[static_cast<std::size_t>(f)]);
            for (std::size_t b = 0; b < sizeof(FaceFrame); b += 64) __builtin_prefetch(line + b);
          }
        }
        tester.face_pair(chunk[i][0], chunk[i][1]);
      }
      tester.flush();
      sink.take(tester, ms_since(c0));
    });
    stats_.set("candidates", static_cast<double>(streamed.candidates));
    stats_.set("stream_ms", ms_since(t1));
    stats_.set("narrow_cpu_ms", sink.narrow_cpu_ms);
  }

  // Orphans (sub-pairs of faces sharing a vertex) and the vertices of no face.
  const auto t2 = std::chrono::steady_clock::now();
  const auto& ovf = s.orphans.vf;
  const auto& oee = s.orphans.ee;
  if (step.moved == nullptr) {
    // With a motion bound, the orphans around a calm vertex (its closed one-ring moves within
    // the reach, none exempt) are dropped: their four vertices lie in that one-ring.
    const bool by_motion = step.face_motion != nullptr;
    if (by_motion) {
      if (s.orphan_hub.size() != ovf.size() + oee.size()) s.orphan_hub = orphan_hubs(topo, s.orphans);
      const auto nv = static_cast<std::size_t>(topo.num_vertices());
      s.calm.resize(nv);
      for (std::size_t v = 0; v < nv; ++v) {
        MotionTree::MotionBox ring{step.motion[v], step.motion[v], step.exempt[v] != 0};
        for (const Index f : topo.vertex_faces()[static_cast<Index>(v)]) {
          MotionTree::merge(ring, step.face_motion[static_cast<std::size_t>(f)]);
        }
        s.calm[v] = MotionTree::together(ring, ring, step.reach2);
      }
    }
    const auto calm = [&](std::size_t orphan) {
      const Index hub = s.orphan_hub[orphan];
      return hub >= 0 && s.calm[static_cast<std::size_t>(hub)];
    };
    parallel_for_chunks(ovf.size(), threads, 4096, [&](std::size_t begin, std::size_t end) {
      Tester tester(step, earliest);
      for (std::size_t i = begin; i < end; ++i) {
        if (by_motion && calm(i)) {
          ++tester.counts.orphans_calm;
          continue;
        }
        tester.orphan_vertex_face(ovf[i][0], ovf[i][1]);
      }
      sink.take(tester, 0);
    });
    parallel_for_chunks(oee.size(), threads, 4096, [&](std::size_t begin, std::size_t end) {
      Tester tester(step, earliest);
      for (std::size_t i = begin; i < end; ++i) {
        if (by_motion && calm(ovf.size() + i)) {
          ++tester.counts.orphans_calm;
          continue;
        }
        tester.orphan_edge_edge(oee[i]);
      }
      sink.take(tester, 0);
    });
  } else {
    // The orphans holding a flagged vertex, from the per-vertex index (built once), each once:
    // `orphan_seen` holds, per orphan (VF first, then EE), the stamp of the last gather that
    // took it (the order of the tests does not matter: the impacts are sorted).
    if (s.orphans_of.vf_begin.empty()) s.orphans_of = index_orphans(topo, s.orphans);
    s.orphan_seen.resize(ovf.size() + oee.size(), 0);
    if (++s.orphan_stamp == 0) {  // wrapped around: start the stamps over
      std::fill(s.orphan_seen.begin(), s.orphan_seen.end(), 0);
      s.orphan_stamp = 1;
    }
    const auto gather = [&](const std::vector<std::size_t>& begin, const std::vector<std::uint32_t>& at,
                            std::size_t offset) {
      std::vector<std::uint32_t> list;
      for (std::size_t v = 0; v < moved.size(); ++v) {
        if (!moved[v]) continue;
        for (std::size_t k = begin[v]; k < begin[v + 1]; ++k) {
          std::uint32_t& seen = s.orphan_seen[offset + at[k]];
          if (seen == s.orphan_stamp) continue;
          seen = s.orphan_stamp;
          list.push_back(at[k]);
        }
      }
      return list;
    };
    const std::vector<std::uint32_t> vf_list = gather(s.orphans_of.vf_begin, s.orphans_of.vf, 0);
    const std::vector<std::uint32_t> ee_list = gather(s.orphans_of.ee_begin, s.orphans_of.ee, ovf.size());
    parallel_for_chunks(vf_list.size(), threads, 1024, [&](std::size_t begin, std::size_t end) {
      Tester tester(step, earliest);
      for (std::size_t i = begin; i < end; ++i) tester.orphan_vertex_face(ovf[vf_list[i]][0], ovf[vf_list[i]][1]);
      sink.take(tester, 0);
    });
    parallel_for_chunks(ee_list.size(), threads, 1024, [&](std::size_t begin, std::size_t end) {
      Tester tester(step, earliest);
      for (std::size_t i = begin; i < end; ++i) tester.orphan_edge_edge(oee[ee_list[i]]);
      sink.take(tester, 0);
    });
  }
  // Around the stars, the orphan sub-pairs of the face pairs whose swept boxes meet
  // (exact/stars.hpp); the vertices of no face against the faces whose swept boxes they meet.
  std::atomic<std::size_t> star_pairs{0};
  parallel_for_chunks(s.orphans.stars.size(), threads, 1, [&](std::size_t begin, std::size_t end) {
    Tester tester(step, earliest);
    exact::StarScratch scratch;
    for (std::size_t i = begin; i < end; ++i) {
      const Index v = s.orphans.stars[i];
      // The orphan sub-pairs of star v lie in faces around v: none is wanted unless one of
      // those faces touches a flagged vertex.
      if (step.moved != nullptr) {
        bool any = false;
        for (const Index f : topo.vertex_faces()[v]) {
          for (const Index u : topo.face(f)) any = any || flagged(u);
        }
        if (!any) continue;
      }
      star_pairs += exact::star_pairs(
          topo, v, scratch, face_box, [&](Index f) { return exact::owned_far_box(topo, s.own, f, v, half, swept_box); },
          [&](Index f, Index g) {
            exact::for_each_orphan(
                topo, s.own, f, g, [&](Index u, Index face) { tester.vertex_face(u, face); },
                [&](Index e0, Index e1) { tester.edge_edge(e0, e1); });
          });
    }
    sink.take(tester, 0);
  });
  const std::vector<Index>& isolated = s.own.isolated;
  if (!isolated.empty()) {
    std::vector<Box> boxes(static_cast<std::size_t>(topo.num_faces()));
    for (std::size_t f = 0; f < boxes.size(); ++f) boxes[f] = face_box(static_cast<Index>(f));
    detail::BoxTree tree;
    tree.build(boxes);
    parallel_for_chunks(isolated.size(), threads, 64, [&](std::size_t begin, std::size_t end) {
      Tester tester(step, earliest);
      for (std::size_t i = begin; i < end; ++i) {
        Box near = swept_box(isolated[i]);
        near.inflate(half);
        tree.query(near, [&](std::uint32_t f) { tester.vertex_face(isolated[i], static_cast<Index>(f)); });
      }
      sink.take(tester, 0);
    });
  }
  stats_.set("orphan_ms", ms_since(t2));

  const auto t3 = std::chrono::steady_clock::now();
  sink.merge();
  out = std::move(sink.impacts);
  if (scaled.exponent != 0) {
    for (auto& i : out.vf) i.distance = std::scalbn(i.distance, -scaled.exponent);
    for (auto& i : out.ee) i.distance = std::scalbn(i.distance, -scaled.exponent);
  }
  stats_.set("sort_ms", ms_since(t3));

  double conservative = 0;
  for (const auto& i : out.vf) conservative += i.outcome != geometry::CcdOutcome::kHitTolerance;
  for (const auto& i : out.ee) conservative += i.outcome != geometry::CcdOutcome::kHitTolerance;
  stats_.set("vf_box_rejected", sink.counts.vf_box_rejected);
  stats_.set("ee_box_rejected", sink.counts.ee_box_rejected);
  stats_.set("vf_tests", sink.counts.vf_tests);
  stats_.set("face_pairs_apart", sink.counts.face_pairs_apart);
  if (bound != nullptr) {
    stats_.set("face_pairs_together", sink.counts.face_pairs_together);
    stats_.set("orphans_calm", sink.counts.orphans_calm);
  }
  stats_.set("ee_tests", sink.counts.ee_tests);
  stats_.set("narrow_boxes", sink.counts.boxes);
  stats_.set("narrow_advance_steps", sink.counts.advance_steps);
  for (std::size_t k = 0; k < sink.counts.outcomes.size(); ++k) {
    stats_.set("narrow_" + std::string(geometry::to_string(static_cast<geometry::CcdOutcome>(k))),
               sink.counts.outcomes[k]);
  }
  stats_.set("orphan_vf", static_cast<double>(ovf.size()));
  stats_.set("orphan_ee", static_cast<double>(oee.size()));
  stats_.set("orphan_stars", static_cast<double>(s.orphans.stars.size()));
  stats_.set("orphan_star_pairs", static_cast<double>(star_pairs.load()));
  stats_.set("isolated_vertices", static_cast<double>(isolated.size()));
  stats_.set("vf_impacts", static_cast<double>(out.vf.size()));
  stats_.set("ee_impacts", static_cast<double>(out.ee.size()));
  stats_.set("conservative_hits", conservative);
  stats_.set("total_ms", ms_since(start));
}

Scalar collision_free_step(const ImpactSet& impacts) {
  Scalar t = 1;
  for (const auto& i : impacts.vf) t = std::min(t, i.toi);
  for (const auto& i : impacts.ee) t = std::min(t, i.toi);
  return t;
}

void write_impacts(std::ostream& out, const ImpactSet& impacts) {
  const auto vec = [&](const Vec3& v) {
    for (int k = 0; k < 3; ++k) {
      out << ' ';
      put_double(out, v[k]);
    }
  };
  for (const auto& i : impacts.vf) {
    out << "vf " << i.vertex << ' ' << i.face << ' ';
    put_double(out, i.toi);
    vec(i.barycentric);
    vec(i.normal);
    out << '\n';
  }
  for (const auto& i : impacts.ee) {
    out << "ee " << i.a[0] << ' ' << i.a[1] << ' ' << i.b[0] << ' ' << i.b[1] << ' ';
    put_double(out, i.toi);
    out << ' ';
    put_double(out, i.s);
    out << ' ';
    put_double(out, i.t);
    vec(i.normal);
    out << '\n';
  }
}

void write_impacts_file(const std::filesystem::path& path, const ImpactSet& impacts) {
  write_file_atomically(path, [&](std::ostream& out) { write_impacts(out, impacts); });
}

ImpactSet continuous_impacts(std::shared_ptr<const Topology> topology, PositionsView previous, PositionsView current,
                             const ContinuousOptions& options) {
  ContinuousQuery query(std::move(topology), options);
  ImpactSet out;
  query.query(previous, current, out);
  return out;
}

Scalar collision_free_step(std::shared_ptr<const Topology> topology, PositionsView previous, PositionsView current,
                           const ContinuousOptions& options) {
  ContinuousQuery query(std::move(topology), options);
  return query.collision_free_step(previous, current);
}

bool detail::face_boxes_apart(const FaceBoxes& a, const FaceBoxes& b, Scalar bound, bool avx2) {
  return avx2 && geometry::detail::ccd_has_avx2() ? boxes_apart_avx2(a, b, bound) : boxes_apart(a, b, bound);
}

}  // namespace crumple
