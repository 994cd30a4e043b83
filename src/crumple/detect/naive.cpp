#include <crumple/core/parallel.hpp>
#include <crumple/detect/naive.hpp>
#include <crumple/detect/narrow_phase.hpp>
#include <crumple/geometry/triangle_intersection.hpp>

#include <mutex>

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
  const Scalar h = options().thickness;
  const Scalar h2 = h * h;
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
    collect(static_cast<std::size_t>(nf), threads, out.tt, [&](Index f0, auto& local) {
      const Face& a = topo.face(f0);
      for (Index f1 = f0 + 1; f1 < nf; ++f1) {
        if (topo.faces_adjacent(f0, f1)) continue;
        const Face& b = topo.face(f1);
        if (geometry::triangles_intersect(narrow::at(x, a[0]), narrow::at(x, a[1]), narrow::at(x, a[2]),
                                          narrow::at(x, b[0]), narrow::at(x, b[1]), narrow::at(x, b[2]))) {
          local.push_back({f0, f1});
        }
      }
    });
    stats_.set("tt_pairs", static_cast<double>(nf) * (nf - 1) / 2);
  }
}

}  // namespace crumple
