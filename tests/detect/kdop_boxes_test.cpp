// The kdop detector's node boxes (what the viewer draws for a level of the hierarchy).
#include <crumple/detect/kdop_tree.hpp>
#include <crumple/mesh/shapes.hpp>

#include <gtest/gtest.h>

namespace crumple {
namespace {

bool inside(const Vec3& p, const Bounds& b) {
  return (p.array() >= b.min.array()).all() && (p.array() <= b.max.array()).all();
}

TEST(KdopBoxes, LevelsCoverTheMeshAndNest) {
  const TriMesh mesh = shapes::lattice(12, 12, 1, 1);
  KdopDetector d({.thickness = 0.01}, KdopParams{});
  EXPECT_EQ(d.levels(), 0);
  EXPECT_TRUE(d.node_boxes(0).empty()) << "no tree before the first update";
  d.set_topology(mesh.topology_ptr());
  ContactSet out;
  d.update(mesh.positions(), out);
  ASSERT_GE(d.levels(), 3);  // 288 faces, arity 4, leaves of at most 4 faces
  const std::vector<Bounds> root = d.node_boxes(0);
  ASSERT_EQ(root.size(), 1u);
  for (const Vec3& p : mesh.positions()) EXPECT_TRUE(inside(p, root[0]));
  // Inflated by half the thickness (at least): the root is larger than the mesh's bounds.
  const Bounds tight = compute_bounds(mesh.positions());
  EXPECT_LT(root[0].min.x(), tight.min.x());
  EXPECT_GT(root[0].max.z(), tight.max.z());
  std::size_t previous = 1;
  for (int depth = 1; depth < d.levels(); ++depth) {
    const std::vector<Bounds> boxes = d.node_boxes(depth);
    EXPECT_GT(boxes.size(), previous) << "depth " << depth;
    previous = boxes.size();
    for (const Bounds& b : boxes) {
      EXPECT_TRUE(inside(b.min, root[0]) && inside(b.max, root[0])) << "depth " << depth;
    }
  }
  // The root's children: one box per quarter (arity 4), which together hold every vertex.
  const std::vector<Bounds> children = d.node_boxes(1);
  EXPECT_EQ(children.size(), 4u);
  for (const Vec3& p : mesh.positions()) {
    bool found = false;
    for (const Bounds& b : children) found = found || inside(p, b);
    EXPECT_TRUE(found);
  }
  EXPECT_TRUE(d.node_boxes(d.levels()).empty());
  EXPECT_TRUE(d.node_boxes(-1).empty());
}

}  // namespace
}  // namespace crumple
