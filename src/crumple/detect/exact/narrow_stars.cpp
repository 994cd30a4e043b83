#include <crumple/core/parallel.hpp>
#include <crumple/detect/broad_phase/box_tree_detail.hpp>
#include <crumple/detect/exact/narrow_frame.hpp>
#include <crumple/detect/exact/stars.hpp>

#include <atomic>
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

}  // namespace

std::size_t narrow_stars(NarrowFrame& frame, const std::vector<Index>& stars, const FeatureOwnership& own) {
  if (!frame.proximity || stars.empty()) return 0;
  const Topology& topo = frame.topo;
  const Scalar r = frame.pad / 2;
  const auto point_box = [&](Index u) {
    Box b = Box::empty();
    b.grow(narrow::at(frame.x, u));
    return b;
  };
  std::atomic<std::size_t> examined{0};
  parallel_for_chunks(stars.size(), frame.threads, 1, [&](std::size_t begin, std::size_t end) {
    LocalContacts local{frame.spares.take()};
    StarScratch scratch;
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
      examined += star_pairs(
          topo, v, scratch,
          [&](Index f) { return corner_box(frame, frame.packed[static_cast<std::size_t>(f)], r); },
          [&](Index f) { return owned_far_box(topo, own, f, v, r, point_box); },
          [&](Index f, Index g) { for_each_orphan(topo, own, f, g, vf, ee); });
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
  detail::BoxTree tree;
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
