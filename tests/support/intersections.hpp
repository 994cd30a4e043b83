#pragma once
// The intersecting triangle pairs of a state, as the tests of the fail-safe and the untangler
// count them.

#include <crumple/detect/detector.hpp>
#include <crumple/detect/method.hpp>
#include <crumple/geometry/triangle_intersection.hpp>
#include <crumple/mesh/mesh.hpp>

#include <memory>
#include <utility>
#include <vector>

namespace crumple::testing {

/// Intersecting triangle pairs (faces sharing no vertex) at `x`, by the exact kdop detector.
inline std::vector<TriangleTriangleContact> intersecting_triangles(std::shared_ptr<const Topology> topology,
                                                                   PositionsView x) {
  DetectorOptions options;
  options.kinds = ContactKinds::parse("tt");
  options.threads = 1;
  auto detector = make_detector(MethodSpec::parse("kdop"), options);
  detector->set_topology(std::move(topology));
  ContactSet contacts;
  detector->update(x, contacts);
  return std::move(contacts.tt);
}

}  // namespace crumple::testing

namespace crumple::testing {

/// Intersecting face pairs of a mesh, every pair of faces tried (no detector, no star walk).
struct ExactIntersections {
  std::size_t disjoint = 0;  ///< faces sharing no vertex that intersect (the `tt` pairs)
  std::size_t pinches = 0;   ///< faces sharing exactly one vertex that meet elsewhere too
};

/// Tries every face pair whose boxes overlap: sharing no vertex, `triangles_intersect`;
/// sharing one vertex v, whether they meet beyond v, i.e. whether the side opposite v of one
/// meets the other (their common part is then a segment from v, which leaves the pair through
/// such a side). Pairs sharing a side are not counted. O(#F²).
inline ExactIntersections exact_intersections(const Topology& topology, PositionsView x) {
  ExactIntersections out;
  const auto box = [&](const Face& f) {
    Vec3 lo = x[static_cast<std::size_t>(f[0])], hi = lo;
    for (Index v : f) {
      lo = lo.cwiseMin(x[static_cast<std::size_t>(v)]);
      hi = hi.cwiseMax(x[static_cast<std::size_t>(v)]);
    }
    return std::pair{lo, hi};
  };
  std::vector<std::pair<Vec3, Vec3>> boxes;
  for (Index f = 0; f < topology.num_faces(); ++f) boxes.push_back(box(topology.face(f)));
  const auto p = [&](Index v) -> const Vec3& { return x[static_cast<std::size_t>(v)]; };
  for (Index i = 0; i < topology.num_faces(); ++i) {
    for (Index j = i + 1; j < topology.num_faces(); ++j) {
      const auto& [lo0, hi0] = boxes[static_cast<std::size_t>(i)];
      const auto& [lo1, hi1] = boxes[static_cast<std::size_t>(j)];
      if ((lo0.array() > hi1.array()).any() || (lo1.array() > hi0.array()).any()) continue;
      const Face& a = topology.face(i);
      const Face& b = topology.face(j);
      int shared = 0;
      Index v = -1;
      for (Index u : a) {
        if (u == b[0] || u == b[1] || u == b[2]) {
          ++shared;
          v = u;
        }
      }
      if (shared == 0) {
        out.disjoint += geometry::triangles_intersect(p(a[0]), p(a[1]), p(a[2]), p(b[0]), p(b[1]), p(b[2]));
      } else if (shared == 1) {
        const auto opposite_meets = [&](const Face& f, const Face& g) {
          Index q = -1, r = -1;
          for (Index u : f) {
            if (u == v) continue;
            (q < 0 ? q : r) = u;
          }
          return geometry::segment_triangle_intersect(p(q), p(r), p(g[0]), p(g[1]), p(g[2]));
        };
        out.pinches += opposite_meets(a, b) || opposite_meets(b, a);
      }
    }
  }
  return out;
}

}  // namespace crumple::testing
