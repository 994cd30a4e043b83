// The kdop detector's node boxes (what the viewer draws for a level of the hierarchy).
#include <crumple/detect/kdop_tree.hpp>
#include <crumple/mesh/shapes.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>

#include "support/meshes.hpp"

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

// The default 18-DOP's leaves are refitted by a vectorised path, a swept tree's by the generic
// one; swept with no motion, the generic one gives the same slabs, so every node's box (its
// x, y and z slabs in double, bit for bit) must be the same, NaN corners included (both skip
// them). The diagonal slabs and the float lanes are not visible here (they were compared leaf
// by leaf on the real scenes with a throw-away build).
TEST(KdopBoxes, VectorisedLeafRefitMatchesTheGenericOne) {
  const TriMesh sheet = shapes::lattice(20, 20);
  for (int variant = 0; variant < 3; ++variant) {
    SCOPED_TRACE("variant " + std::to_string(variant));
    Positions x = testing::crumple_lattice(sheet, 0.3, 11 + static_cast<std::uint64_t>(variant));
    if (variant == 1) {
      for (Vec3& p : x) p = 1e35 * p + Vec3(1e36, -3e35, 0);  // large coordinates, far from the origin
    }
    if (variant == 2) {
      x[7].y() = std::nan("");
      x[30] = Vec3(-0.0, 0.0, -0.0);
    }
    KdopParams plain, swept;
    plain.coherence = swept.coherence = false;
    plain.leaf = swept.leaf = 16;
    swept.sweep = true;
    const Scalar h = 0.02 * (variant == 1 ? 1e35 : 1);
    KdopDetector fast({.thickness = h, .threads = 1}, plain), generic({.thickness = h, .threads = 1}, swept);
    fast.set_topology(sheet.topology_ptr());
    generic.set_topology(sheet.topology_ptr());
    ContactSet out;
    fast.update(x, out);
    generic.update(x, x, out);
    ASSERT_EQ(fast.levels(), generic.levels());
    ASSERT_GE(fast.levels(), 3);
    for (int depth = 0; depth < fast.levels(); ++depth) {
      const std::vector<Bounds> a = fast.node_boxes(depth), b = generic.node_boxes(depth);
      ASSERT_EQ(a.size(), b.size());
      for (std::size_t n = 0; n < a.size(); ++n) {
        EXPECT_EQ(std::memcmp(&a[n], &b[n], sizeof(Bounds)), 0)
            << "depth " << depth << " node " << n << ": " << a[n].min.transpose() << " / " << b[n].min.transpose();
      }
    }
  }
}

}  // namespace
}  // namespace crumple
