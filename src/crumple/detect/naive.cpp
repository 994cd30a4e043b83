#include <crumple/core/parallel.hpp>
#include <crumple/detect/naive.hpp>
#include <crumple/detect/narrow_phase.hpp>
#include <crumple/geometry/triangle_intersection.hpp>

#include <algorithm>
#include <atomic>
#include <cstdint>
#include <limits>
#include <mutex>
#include <vector>

namespace crumple {

namespace {

/// Runs `per_row(i, local)` for i in [0, n) in parallel chunks and appends every chunk's local
/// results to `out` (order fixed later by the final sort).
template <class T, class PerRow>
void collect(std::size_t n, int threads, std::vector<T>& out, const PerRow& per_row) {
  std::mutex mutex;
  parallel_for_chunks(n, threads, 16, [&](std::size_t begin, std::size_t end) {
    std::vector<T> local;
    for (std::size_t i = begin; i < end; ++i) per_row(static_cast<Index>(i), local);
    const std::lock_guard lock(mutex);
    out.insert(out.end(), local.begin(), local.end());
  });
}

/// An axis-aligned box; `apart` is exact on the stored bounds.
struct Box {
  Vec3 lo, hi;
  bool apart(const Box& o) const { return (hi.array() < o.lo.array()).any() || (o.hi.array() < lo.array()).any(); }
};

/// The bounding box of points a, b (and c), grown by pad on every side; unbounded when a
/// coordinate is not finite, so that such a feature is never culled (its exact test decides).
Box padded_box(const Vec3& a, const Vec3& b, const Vec3& c, Scalar pad) {
  if (!(a.allFinite() && b.allFinite() && c.allFinite())) {
    const Scalar inf = std::numeric_limits<Scalar>::infinity();
    return {Vec3::Constant(-inf), Vec3::Constant(inf)};
  }
  return {a.cwiseMin(b).cwiseMin(c).array() - pad, a.cwiseMax(b).cwiseMax(c).array() + pad};
}

/// Calls `per_pair(i, j, local)` (i < j) for every pair of boxes that are not apart, rows in
/// parallel: the all-pairs loop's pairs, met in another order. Sorted by their lower x bound, a
/// later box that starts past a row's upper x bound is apart from it, and so is every box after.
/// Returns how many calls returned true.
template <class T, class PerPair>
std::uint64_t overlapping_pairs(const std::vector<Box>& boxes, int threads, std::vector<T>& out,
                                const PerPair& per_pair) {
  std::vector<Index> order(boxes.size());
  for (std::size_t i = 0; i < order.size(); ++i) order[i] = static_cast<Index>(i);
  const auto lower = [&](Index i) { return boxes[static_cast<std::size_t>(i)].lo.x(); };
  std::sort(order.begin(), order.end(), [&](Index a, Index b) { return lower(a) < lower(b) || (lower(a) == lower(b) && a < b); });
  std::atomic<std::uint64_t> counted{0};
  collect(order.size(), threads, out, [&](Index row, auto& local) {
    const Index i = order[static_cast<std::size_t>(row)];
    const Box& box = boxes[static_cast<std::size_t>(i)];
    std::uint64_t n = 0;
    for (std::size_t k = static_cast<std::size_t>(row) + 1; k < order.size() && lower(order[k]) <= box.hi.x(); ++k) {
      const Index j = order[k];
      if (!box.apart(boxes[static_cast<std::size_t>(j)]) && per_pair(std::min(i, j), std::max(i, j), local)) ++n;
    }
    counted += n;
  });
  return counted.load();
}

}  // namespace

void NaiveDetector::detect(PositionsView /*previous*/, PositionsView x, ContactSet& out) {
  out.clear();
  const Topology& topo = topology();
  const Scalar h2 = narrow::sqr_thickness(thickness());
  const int threads = options().threads;
  const Index nv = topo.num_vertices();
  const Index nf = topo.num_faces();
  const Index ne = topo.num_edges();

  // The cull's pad (as the exact detectors'): a computed distance below h needs a true one
  // below h (1 + 1e-6) + 1e-9 × the largest coordinate, far above the kernels' rounding. Boxes
  // grown by pad / 2 each are then apart only for pairs the exact test rejects. Without the cull
  // every box is unbounded.
  Scalar magnitude = 0;  // std::max keeps it for a NaN; an infinity makes the pad infinite
  for (const Vec3& p : x) magnitude = std::max(magnitude, p.cwiseAbs().maxCoeff());
  const Scalar pad = cull_ ? thickness() * (1 + 1e-6) + 1e-9 * magnitude : std::numeric_limits<Scalar>::infinity();
  const auto p_at = [&](Index v) -> const Vec3& { return narrow::at(x, v); };
  const auto face_box = [&](Index f, Scalar grow) {
    const Face& t = topo.face(f);
    return padded_box(p_at(t[0]), p_at(t[1]), p_at(t[2]), grow);
  };
  if (options().kinds.vf) {
    // Rows are faces. The vertices are sorted by x: their boxes share one width and rounding is
    // monotone, so both bounds are sorted and the vertices whose x range meets a face's form one
    // run, found by bisection. A vertex with a non-finite coordinate has an unbounded box.
    std::vector<Index> sorted, unbounded;
    for (Index v = 0; v < nv; ++v) (p_at(v).allFinite() ? sorted : unbounded).push_back(v);
    std::sort(sorted.begin(), sorted.end(),
              [&](Index a, Index b) { return p_at(a).x() < p_at(b).x() || (p_at(a).x() == p_at(b).x() && a < b); });
    const auto vertex_box = [&](Index v) { return padded_box(p_at(v), p_at(v), p_at(v), pad / 2); };
    std::atomic<std::uint64_t> exact_tests{0};
    collect(static_cast<std::size_t>(nf), threads, out.vf, [&](Index f, auto& local) {
      const Box face = face_box(f, pad / 2);
      const auto first = std::partition_point(sorted.begin(), sorted.end(),
                                              [&](Index v) { return vertex_box(v).hi.x() < face.lo.x(); });
      const auto last =
          std::partition_point(first, sorted.end(), [&](Index v) { return vertex_box(v).lo.x() <= face.hi.x(); });
      std::uint64_t tests = 0;
      const auto test = [&](Index v) {
        if (vertex_box(v).apart(face) || topo.face_has_vertex(f, v)) return;
        ++tests;
        if (auto c = narrow::vertex_face(x, topo, v, f, h2)) local.push_back(*c);
      };
      std::for_each(first, last, test);
      std::for_each(unbounded.begin(), unbounded.end(), test);
      exact_tests += tests;
    });
    stats_.set("vf_tests", static_cast<double>(nv) * nf - 3.0 * nf);
    stats_.set("vf_exact_tests", static_cast<double>(exact_tests.load()));
  }
  if (options().kinds.ee) {
    std::vector<Box> edges(static_cast<std::size_t>(ne));
    for (Index e = 0; e < ne; ++e) {
      const Edge& ab = topo.edge(e);
      edges[static_cast<std::size_t>(e)] = padded_box(p_at(ab[0]), p_at(ab[1]), p_at(ab[1]), pad / 2);
    }
    const std::uint64_t tests = overlapping_pairs(edges, threads, out.ee, [&](Index e0, Index e1, auto& local) {
      if (topo.edges_adjacent(e0, e1)) return false;
      if (auto c = narrow::edge_edge(x, topo, e0, e1, h2)) local.push_back(*c);
      return true;
    });
    stats_.set("ee_pairs", static_cast<double>(ne) * (ne - 1) / 2);
    stats_.set("ee_exact_tests", static_cast<double>(tests));
  }
  if (options().kinds.tt) {
    // Closed triangles lie in their closed bounding boxes, so disjoint boxes (compared exactly,
    // on the input coordinates) prove a pair disjoint: the result is the all-pairs exact test's.
    // It spares the exact test, slowest on coplanar pairs (a flat sheet), for distant pairs.
    std::vector<Box> boxes(static_cast<std::size_t>(nf));
    for (Index f = 0; f < nf; ++f) boxes[static_cast<std::size_t>(f)] = face_box(f, cull_ ? 0 : pad);
    const std::uint64_t tests = overlapping_pairs(boxes, threads, out.tt, [&](Index f0, Index f1, auto& local) {
      if (topo.faces_adjacent(f0, f1)) return false;
      const Face& a = topo.face(f0);
      const Face& b = topo.face(f1);
      if (geometry::triangles_intersect(p_at(a[0]), p_at(a[1]), p_at(a[2]), p_at(b[0]), p_at(b[1]), p_at(b[2]))) {
        local.push_back({f0, f1});
      }
      return true;
    });
    stats_.set("tt_pairs", static_cast<double>(nf) * (nf - 1) / 2);
    stats_.set("tt_exact_tests", static_cast<double>(tests));
  }
}

}  // namespace crumple
