// The kdop detector's node boxes (what the viewer draws for a level of the hierarchy) and leaves.
#include <crumple/detect/broad_phase/kdop_tree.hpp>
#include <crumple/detect/exact_detector.hpp>
#include <crumple/io/mesh_io.hpp>
#include <crumple/mesh/shapes.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <memory>
#include <cmath>
#include <cstring>
#include <numeric>
#include <string>
#include <vector>

#include "support/meshes.hpp"

namespace crumple {
namespace {

/// The exact detector over a k-DOP tree (what `make_detector` builds for `kdop`).
ExactDetector kdop_detector(DetectorOptions options, const KdopParams& params) {
  return ExactDetector(options, ExactParams{}, std::make_unique<KdopTree>(params));
}

/// Its hierarchy, as the viewer sees it.
const BoundingHierarchy& tree(const Detector& d) { return *d.hierarchy(); }

bool inside(const Vec3& p, const Bounds& b) {
  return (p.array() >= b.min.array()).all() && (p.array() <= b.max.array()).all();
}

/// Number of pieces of `faces` connected by shared vertices.
std::size_t pieces(const Topology& topo, const std::vector<Index>& faces) {
  std::vector<std::size_t> root(faces.size());
  std::iota(root.begin(), root.end(), std::size_t{0});
  const auto find = [&](std::size_t a) {
    while (root[a] != a) a = root[a] = root[root[a]];
    return a;
  };
  for (std::size_t i = 0; i < faces.size(); ++i) {
    for (std::size_t j = i + 1; j < faces.size(); ++j) {
      if (faces_share_vertex(topo.face(faces[i]), topo.face(faces[j]))) root[find(i)] = find(j);
    }
  }
  std::size_t count = 0;
  for (std::size_t i = 0; i < faces.size(); ++i) count += find(i) == i ? 1 : 0;
  return count;
}

/// The leaves partition the faces into connected patches of 1..leaf faces.
void expect_patch_leaves(const Detector& d, const Topology& topo, int leaf) {
  const std::vector<std::vector<Index>> leaves = tree(d).leaf_faces();
  ASSERT_FALSE(leaves.empty());
  std::vector<int> seen(static_cast<std::size_t>(topo.num_faces()), 0);
  std::size_t broken = 0;
  for (const std::vector<Index>& faces : leaves) {
    EXPECT_GE(faces.size(), 1u);
    EXPECT_LE(faces.size(), static_cast<std::size_t>(leaf));
    for (const Index f : faces) ++seen[static_cast<std::size_t>(f)];
    broken += pieces(topo, faces) == 1 ? 0 : 1;
  }
  EXPECT_EQ(broken, 0u) << "of " << leaves.size() << " leaves";
  for (Index f = 0; f < topo.num_faces(); ++f) EXPECT_EQ(seen[static_cast<std::size_t>(f)], 1) << "face " << f;
}

// Every leaf is one connected patch (faces linked by shared vertices), whatever the leaf size
// and arity, on meshes whose sheets pass near each other: leaves of plain median cuts mixed
// pieces of several there (armadillo's 326: 546 of 640 leaves), which move apart. Also after a
// rebuild from other positions (rebuild=1: on every frame whose tree loosened at all), which
// keeps the patches of the first build, so the same leaves.
TEST(KdopBoxes, LeavesAreConnectedPatches) {
  std::vector<std::pair<std::string, TriMesh>> meshes = testing::small_meshes();
  meshes.emplace_back("folded24", shapes::folded_cloth({.n = 24, .gap = 0.02, .wave = 0.01, .thickness = 0.04}));
  const TriMesh lattice = shapes::lattice(30, 30, 1, 1);
  const auto faces = lattice.topology().faces();
  meshes.emplace_back("crumpled30", TriMesh::create(testing::crumple_lattice(lattice, 0.3, 7), {faces.begin(), faces.end()}));
  meshes.emplace_back("armadillo", io::read_mesh(testing::data_path("sample-scalable-ccd/armadillo-rollers/frames/326.ply")));
  const Positions armadillo_next =
      io::read_mesh(testing::data_path("sample-scalable-ccd/armadillo-rollers/frames/327.ply")).positions();
  for (const auto& [name, mesh] : meshes) {
    for (const int leaf : {48, 16, 5}) {
      for (const int arity : {2, 4, 8}) {
        SCOPED_TRACE(name + " leaf=" + std::to_string(leaf) + " arity=" + std::to_string(arity));
        KdopParams params;
        params.arity = arity;
        params.leaf = leaf;
        params.rebuild = 1;
        ExactDetector d = kdop_detector({.thickness = 1e-3}, params);
        d.set_topology(mesh.topology_ptr());
        ContactSet out;
        d.update(mesh.positions(), out);
        expect_patch_leaves(d, mesh.topology(), leaf);
        if (name == "armadillo") {
          // The rebuild keeps the patches grown at the first build: the same leaves.
          const auto sorted_leaves = [&d] {
            std::vector<std::vector<Index>> leaves = tree(d).leaf_faces();
            for (std::vector<Index>& faces : leaves) std::sort(faces.begin(), faces.end());
            std::sort(leaves.begin(), leaves.end());
            return leaves;
          };
          const std::vector<std::vector<Index>> before = sorted_leaves();
          d.update(mesh.positions(), armadillo_next, out);
          EXPECT_EQ(d.stats().get("rebuilds"), 1);
          expect_patch_leaves(d, mesh.topology(), leaf);
          EXPECT_EQ(sorted_leaves(), before);
        }
      }
    }
  }
}

TEST(KdopBoxes, LevelsCoverTheMeshAndNest) {
  const TriMesh mesh = shapes::lattice(12, 12, 1, 1);
  ExactDetector d = kdop_detector({.thickness = 0.01}, KdopParams{});
  EXPECT_EQ(tree(d).levels(), 0);
  EXPECT_TRUE(tree(d).node_boxes(0).empty()) << "no tree before the first update";
  d.set_topology(mesh.topology_ptr());
  ContactSet out;
  d.update(mesh.positions(), out);
  ASSERT_GE(tree(d).levels(), 3);  // 288 faces, arity 4, leaves of one patch of at most 48 faces
  const std::vector<Bounds> root = tree(d).node_boxes(0);
  ASSERT_EQ(root.size(), 1u);
  for (const Vec3& p : mesh.positions()) EXPECT_TRUE(inside(p, root[0]));
  // Inflated by half the thickness (at least): the root is larger than the mesh's bounds.
  const Bounds tight = compute_bounds(mesh.positions());
  EXPECT_LT(root[0].min.x(), tight.min.x());
  EXPECT_GT(root[0].max.z(), tight.max.z());
  // (A depth holds the children of the one above; leaves of one patch end at several depths.)
  for (int depth = 1; depth < tree(d).levels(); ++depth) {
    const std::vector<Bounds> boxes = tree(d).node_boxes(depth);
    EXPECT_FALSE(boxes.empty()) << "depth " << depth;
    for (const Bounds& b : boxes) {
      EXPECT_TRUE(inside(b.min, root[0]) && inside(b.max, root[0])) << "depth " << depth;
    }
  }
  // The root's children: one box per quarter (arity 4), which together hold every vertex.
  const std::vector<Bounds> children = tree(d).node_boxes(1);
  EXPECT_EQ(children.size(), 4u);
  for (const Vec3& p : mesh.positions()) {
    bool found = false;
    for (const Bounds& b : children) found = found || inside(p, b);
    EXPECT_TRUE(found);
  }
  EXPECT_TRUE(tree(d).node_boxes(tree(d).levels()).empty());
  EXPECT_TRUE(tree(d).node_boxes(-1).empty());
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
    ExactDetector fast = kdop_detector({.thickness = h, .threads = 1}, plain);
    ExactDetector generic = kdop_detector({.thickness = h, .threads = 1}, swept);
    fast.set_topology(sheet.topology_ptr());
    generic.set_topology(sheet.topology_ptr());
    ContactSet out;
    fast.update(x, out);
    generic.update(x, x, out);
    ASSERT_EQ(tree(fast).levels(), tree(generic).levels());
    ASSERT_GE(tree(fast).levels(), 3);
    for (int depth = 0; depth < tree(fast).levels(); ++depth) {
      const std::vector<Bounds> a = tree(fast).node_boxes(depth), b = tree(generic).node_boxes(depth);
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
