#include <crumple/core/parallel.hpp>
#include <crumple/detect/naive.hpp>
#include <crumple/detect/narrow_phase.hpp>
#include <crumple/geometry/triangle_intersection.hpp>

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
  std::atomic<std::uint64_t> exact_tests{0};

  if (options().kinds.vf) {
    std::vector<Box> faces(static_cast<std::size_t>(nf));
    for (Index f = 0; f < nf; ++f) {
      const Face& t = topo.face(f);
      faces[static_cast<std::size_t>(f)] = padded_box(p_at(t[0]), p_at(t[1]), p_at(t[2]), pad / 2);
    }
    exact_tests = 0;
    collect(static_cast<std::size_t>(nv), threads, out.vf, [&](Index v, auto& local) {
      const Box vertex = padded_box(p_at(v), p_at(v), p_at(v), pad / 2);
      std::uint64_t tests = 0;
      for (Index f = 0; f < nf; ++f) {
        if (vertex.apart(faces[static_cast<std::size_t>(f)]) || topo.face_has_vertex(f, v)) continue;
        ++tests;
        if (auto c = narrow::vertex_face(x, topo, v, f, h2)) local.push_back(*c);
      }
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
    exact_tests = 0;
    collect(static_cast<std::size_t>(ne), threads, out.ee, [&](Index e0, auto& local) {
      const Box& box0 = edges[static_cast<std::size_t>(e0)];
      std::uint64_t tests = 0;
      for (Index e1 = e0 + 1; e1 < ne; ++e1) {
        if (box0.apart(edges[static_cast<std::size_t>(e1)]) || topo.edges_adjacent(e0, e1)) continue;
        ++tests;
        if (auto c = narrow::edge_edge(x, topo, e0, e1, h2)) local.push_back(*c);
      }
      exact_tests += tests;
    });
    stats_.set("ee_pairs", static_cast<double>(ne) * (ne - 1) / 2);
    stats_.set("ee_exact_tests", static_cast<double>(exact_tests.load()));
  }
  if (options().kinds.tt) {
    // Closed triangles lie in their closed bounding boxes, so disjoint boxes (compared exactly,
    // on the input coordinates) prove a pair disjoint: the result is the all-pairs exact test's.
    // It spares the exact test, slowest on coplanar pairs (a flat sheet), for distant pairs.
    std::vector<Box> boxes(static_cast<std::size_t>(nf));
    for (Index f = 0; f < nf; ++f) {
      const Face& t = topo.face(f);
      boxes[static_cast<std::size_t>(f)] = padded_box(p_at(t[0]), p_at(t[1]), p_at(t[2]), cull_ ? 0 : pad);
    }
    exact_tests = 0;
    collect(static_cast<std::size_t>(nf), threads, out.tt, [&](Index f0, auto& local) {
      const Face& a = topo.face(f0);
      const Box& box0 = boxes[static_cast<std::size_t>(f0)];
      std::uint64_t tests = 0;
      for (Index f1 = f0 + 1; f1 < nf; ++f1) {
        const Box& box1 = boxes[static_cast<std::size_t>(f1)];
        if (box0.apart(box1)) continue;
        if (topo.faces_adjacent(f0, f1)) continue;
        ++tests;
        const Face& b = topo.face(f1);
        if (geometry::triangles_intersect(narrow::at(x, a[0]), narrow::at(x, a[1]), narrow::at(x, a[2]),
                                          narrow::at(x, b[0]), narrow::at(x, b[1]), narrow::at(x, b[2]))) {
          local.push_back({f0, f1});
        }
      }
      exact_tests += tests;
    });
    stats_.set("tt_pairs", static_cast<double>(nf) * (nf - 1) / 2);
    stats_.set("tt_exact_tests", static_cast<double>(exact_tests.load()));
  }
}

}  // namespace crumple
