#include <crumple/core/parallel.hpp>
#include <crumple/detect/naive.hpp>
#include <crumple/detect/narrow_phase.hpp>
#include <crumple/geometry/triangle_intersection.hpp>

#include <atomic>
#include <cstdint>
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

}  // namespace

void NaiveDetector::detect(PositionsView /*previous*/, PositionsView x, ContactSet& out) {
  out.clear();
  const Topology& topo = topology();
  const Scalar h2 = narrow::sqr_thickness(thickness());
  const int threads = options().threads;
  const Index nv = topo.num_vertices();
  const Index nf = topo.num_faces();
  const Index ne = topo.num_edges();

  if (options().kinds.vf) {
    collect(static_cast<std::size_t>(nv), threads, out.vf, [&](Index v, auto& local) {
      for (Index f = 0; f < nf; ++f) {
        if (topo.face_has_vertex(f, v)) continue;
        if (auto c = narrow::vertex_face(x, topo, v, f, h2)) local.push_back(*c);
      }
    });
    stats_.set("vf_tests", static_cast<double>(nv) * nf - 3.0 * nf);
  }
  if (options().kinds.ee) {
    collect(static_cast<std::size_t>(ne), threads, out.ee, [&](Index e0, auto& local) {
      for (Index e1 = e0 + 1; e1 < ne; ++e1) {
        if (topo.edges_adjacent(e0, e1)) continue;
        if (auto c = narrow::edge_edge(x, topo, e0, e1, h2)) local.push_back(*c);
      }
    });
    stats_.set("ee_pairs", static_cast<double>(ne) * (ne - 1) / 2);
  }
  if (options().kinds.tt) {
    // Closed triangles lie in their closed bounding boxes, so disjoint boxes (compared exactly,
    // on the input coordinates) prove a pair disjoint: the result is the all-pairs exact test's.
    // It spares the exact test, slowest on coplanar pairs (a flat sheet), for distant pairs.
    struct Box {
      Vec3 lo, hi;
    };
    std::vector<Box> boxes(static_cast<std::size_t>(nf));
    for (Index f = 0; f < nf; ++f) {
      const Face& t = topo.face(f);
      const Vec3 &p = narrow::at(x, t[0]), &q = narrow::at(x, t[1]), &r = narrow::at(x, t[2]);
      boxes[static_cast<std::size_t>(f)] = {p.cwiseMin(q).cwiseMin(r), p.cwiseMax(q).cwiseMax(r)};
    }
    std::atomic<std::uint64_t> exact_tests{0};
    collect(static_cast<std::size_t>(nf), threads, out.tt, [&](Index f0, auto& local) {
      const Face& a = topo.face(f0);
      const Box& box0 = boxes[static_cast<std::size_t>(f0)];
      std::uint64_t tests = 0;
      for (Index f1 = f0 + 1; f1 < nf; ++f1) {
        const Box& box1 = boxes[static_cast<std::size_t>(f1)];
        if ((box0.hi.array() < box1.lo.array()).any() || (box1.hi.array() < box0.lo.array()).any()) continue;
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
