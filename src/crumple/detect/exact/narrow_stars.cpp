#include <crumple/core/parallel.hpp>
#include <crumple/detect/exact/box_tree.hpp>
#include <crumple/detect/exact/narrow_frame.hpp>

#include <algorithm>
#include <atomic>
#include <utility>
#include <vector>

namespace crumple::exact {

namespace {

/// The box of face t's corners, NaN corners left out (a face's finite side keeps its
/// contacts), inflated by r.
Box corner_box(const NarrowFrame& frame, const PackedFace& t, Scalar r) {
  Box b = Box::empty();
  for (const Index u : t.v) b.grow(narrow::at(frame.x, u));
  b.inflate(r);
  return b;
}

/// The box of the features of face t without vertex v that t owns (its corners other than v,
/// the ends of its sides without v), NaN points left out, inflated by r; empty if none.
Box owned_far_box(const NarrowFrame& frame, const PackedFace& t, Index v, Scalar r) {
  Box b = Box::empty();
  for (std::size_t k = 0; k < 3; ++k) {
    const Index u = t.v[k], w = t.v[(k + 1) % 3];
    if ((t.vertex_mask >> k & 1u) && u != v) b.grow(narrow::at(frame.x, u));
    if ((t.edge_mask >> k & 1u) && u != v && w != v) {
      b.grow(narrow::at(frame.x, u));
      b.grow(narrow::at(frame.x, w));
    }
  }
  b.inflate(r);
  return b;
}

}  // namespace

std::size_t narrow_stars(NarrowFrame& frame, const std::vector<Index>& stars, const FeatureOwnership& own) {
  if (!frame.proximity || stars.empty()) return 0;
  const Topology& topo = frame.topo;
  const Scalar r = frame.pad / 2;
  std::atomic<std::size_t> examined{0};
  parallel_for_chunks(stars.size(), frame.threads, 1, [&](std::size_t begin, std::size_t end) {
    LocalContacts local{frame.spares.take()};
    std::vector<Index> faces;
    std::vector<Box> boxes;
    std::vector<std::pair<Index, Index>> pairs;
    BoxTree tree;
    const auto vf = [&](Index u, Index g) {
      if (!frame.kinds.vf) return;
      const Vec3& p = narrow::at(frame.x, u);
      const PackedFace& t = frame.packed[static_cast<std::size_t>(g)];
      if (frame.in_box(p, t)) frame.vf_kernel(p, u, frame.corner(t, 0), frame.corner(t, 1), frame.corner(t, 2), g, local);
    };
    const auto ee = [&](Index e0, Index e1) {
      if (!frame.kinds.ee) return;
      const Edge a = topo.edge(e0), b = topo.edge(e1);
      frame.ee_kernel(narrow::at(frame.x, a[0]), narrow::at(frame.x, a[1]), a[0], a[1], e0, narrow::at(frame.x, b[0]),
                      narrow::at(frame.x, b[1]), b[0], b[1], e1, local);
    };
    for (std::size_t i = begin; i < end; ++i) {
      const Index v = stars[i];
      const auto around = topo.vertex_faces()[v];
      faces.assign(around.begin(), around.end());
      std::sort(faces.begin(), faces.end());
      faces.erase(std::unique(faces.begin(), faces.end()), faces.end());
      boxes.resize(faces.size());
      for (std::size_t k = 0; k < faces.size(); ++k) boxes[k] = corner_box(frame, frame.packed[static_cast<std::size_t>(faces[k])], r);
      tree.build(boxes);
      // Every orphan sub-pair of two faces f, g around v has an owned feature without v: the
      // vertex of a vertex-face pair (v is on both faces), or one of two edges that share no
      // vertex. So a sub-pair within pad has the box of one face's owned features without v,
      // inflated by pad / 2, meet the other face's box inflated by as much; and a face that owns
      // no such feature asks nothing (so many copies of one face cost linear time).
      pairs.clear();
      for (std::size_t k = 0; k < faces.size(); ++k) {
        const Box far = owned_far_box(frame, frame.packed[static_cast<std::size_t>(faces[k])], v, r);
        if (!(far.lo[0] <= far.hi[0])) continue;  // owns nothing without v (or only NaN)
        tree.query(far, [&](std::uint32_t j) {
          if (j != k) pairs.emplace_back(std::min(faces[k], faces[j]), std::max(faces[k], faces[j]));
        });
      }
      std::sort(pairs.begin(), pairs.end());
      pairs.erase(std::unique(pairs.begin(), pairs.end()), pairs.end());
      examined += pairs.size();
      for (const auto& [f, g] : pairs) {
        if (smallest_shared_vertex(topo, f, g) == v) for_each_orphan(topo, own, f, g, vf, ee);
      }
    }
    frame.collect(local);
  });
  return examined.load();
}

void narrow_isolated(NarrowFrame& frame, const std::vector<Index>& isolated) {
  if (!frame.kinds.vf || isolated.empty()) return;
  // The faces that come within pad of an isolated vertex, from a tree of their boxes: a
  // vertex's box inflated by pad / 2 meets a face's box inflated by as much.
  const Scalar r = frame.pad / 2;
  std::vector<Box> boxes(frame.packed.size());
  parallel_for_chunks(boxes.size(), frame.threads, 4096, [&](std::size_t begin, std::size_t end) {
    for (std::size_t g = begin; g < end; ++g) boxes[g] = corner_box(frame, frame.packed[g], r);
  });
  BoxTree tree;
  tree.build(boxes);
  parallel_for_chunks(isolated.size(), frame.threads, 64, [&](std::size_t begin, std::size_t end) {
    LocalContacts local{frame.spares.take()};
    for (std::size_t i = begin; i < end; ++i) {
      const Index v = isolated[i];
      const Vec3& p = narrow::at(frame.x, v);
      Box near = Box::empty();
      near.grow(p);
      near.inflate(r);
      tree.query(near, [&](std::uint32_t g) {
        const PackedFace& t = frame.packed[g];
        if (frame.in_box(p, t)) {
          frame.vf_kernel(p, v, frame.corner(t, 0), frame.corner(t, 1), frame.corner(t, 2), static_cast<Index>(g), local);
        }
      });
    }
    frame.collect(local);
  });
}

}  // namespace crumple::exact
