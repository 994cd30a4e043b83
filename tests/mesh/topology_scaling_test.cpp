// Regression (issue 45, defect 1): the topology of a high-valence fan or of many copies of one
// face was quadratic in the valence (a 60k-triangle fan ran out of memory). What loading builds
// must grow linearly: doubling the input at most doubles the bytes held.
#include <crumple/mesh/mesh.hpp>

#include <gtest/gtest.h>

#include <vector>

namespace crumple {
namespace {

/// `n` triangles fanning around vertex 0 (an open fan: vertices 1..n+1 on the rim).
std::vector<Face> fan(Index n) {
  std::vector<Face> faces;
  for (Index i = 0; i < n; ++i) faces.push_back({0, i + 1, i + 2});
  return faces;
}

/// `n` copies of one face.
std::vector<Face> copies(Index n) { return std::vector<Face>(static_cast<std::size_t>(n), Face{0, 1, 2}); }

TEST(TopologyScaling, FanMemoryIsLinearInFaces) {
  const Topology small = Topology::build(4002, fan(4000));
  const Topology large = Topology::build(8002, fan(8000));
  EXPECT_LE(large.memory_bytes(), 2 * small.memory_bytes() + 64 * 1024)
      << small.memory_bytes() << " bytes for 4000 faces, " << large.memory_bytes() << " for 8000";
  EXPECT_EQ(large.vertex_faces()[0].size(), 8000u);
  EXPECT_EQ(large.vertex_vertices()[0].size(), 8001u);
}

TEST(TopologyScaling, DuplicateFacesMemoryIsLinearInFaces) {
  const Topology small = Topology::build(3, copies(4000));
  const Topology large = Topology::build(3, copies(8000));
  EXPECT_LE(large.memory_bytes(), 2 * small.memory_bytes() + 64 * 1024)
      << small.memory_bytes() << " bytes for 4000 faces, " << large.memory_bytes() << " for 8000";
  EXPECT_EQ(large.report().duplicate_faces, 7999u);
  EXPECT_EQ(large.num_edges(), 3);
  EXPECT_EQ(large.edge_faces()[0].size(), 8000u);
}

}  // namespace
}  // namespace crumple
