#include <crumple/core/error.hpp>
#include <crumple/mesh/mesh.hpp>
#include <crumple/mesh/shapes.hpp>
#include <support/meshes.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <set>

namespace crumple {
namespace {

TEST(Topology, EdgeOrderIsFirstAppearance) {
  // Two triangles sharing edge (1,2): sides visited (0,1) (1,2) (2,0) then (2,1) (1,3) (3,2).
  const Topology t = Topology::build(4, {{0, 1, 2}, {2, 1, 3}});
  ASSERT_EQ(t.num_edges(), 5);
  const std::vector<Edge> expected{{0, 1}, {1, 2}, {0, 2}, {1, 3}, {2, 3}};
  EXPECT_EQ(std::vector<Edge>(t.edges().begin(), t.edges().end()), expected);
  EXPECT_EQ(t.face_edges(0), (std::array<Index, 3>{0, 1, 2}));
  EXPECT_EQ(t.face_edges(1), (std::array<Index, 3>{1, 3, 4}));
  EXPECT_EQ(std::vector<Index>(t.edge_faces()[1].begin(), t.edge_faces()[1].end()),
            (std::vector<Index>{0, 1}));
  EXPECT_EQ(t.report().boundary_edges, 4u);
  EXPECT_EQ(t.report().non_manifold_edges, 0u);
}

TEST(Topology, RejectsOutOfRangeIndexNamingTheFace) {
  try {
    Topology::build(3, {{0, 1, 2}, {0, 1, 7}});
    FAIL() << "expected InputError";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("face 1"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("7"), std::string::npos) << e.what();
  }
  EXPECT_THROW(Topology::build(3, {{0, -1, 2}}), InputError);
}

TEST(Topology, RejectsRepeatedVertexNamingTheFace) {
  try {
    Topology::build(4, {{0, 1, 2}, {1, 3, 3}});
    FAIL() << "expected InputError";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("face 1"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("repeated"), std::string::npos) << e.what();
  }
}

TEST(TriMesh, RejectsNonFiniteCoordinateNamingTheVertex) {
  for (double bad : {std::numeric_limits<double>::quiet_NaN(), std::numeric_limits<double>::infinity()}) {
    try {
      TriMesh::create({Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, bad, 0)}, {{0, 1, 2}});
      FAIL() << "expected InputError";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("vertex 2"), std::string::npos) << e.what();
    }
  }
}

TEST(TriMesh, ReportCountsAcceptedDefects) {
  // Face 1 is zero-area (collinear), edge (0,1) has three faces, vertex 6 is isolated,
  // face 3 duplicates face 0 with another winding.
  const TriMesh m = TriMesh::create(
      {Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0), Vec3(2, 0, 0), Vec3(0, -1, 0), Vec3(0, 0, 1),
       Vec3(9, 9, 9)},
      {{0, 1, 2}, {0, 1, 3}, {0, 1, 4}, {2, 1, 0}, {0, 1, 5}});
  EXPECT_EQ(m.report().zero_area_faces, 1u);
  EXPECT_EQ(m.report().non_manifold_edges, 1u);
  EXPECT_EQ(m.report().isolated_vertices, 1u);
  EXPECT_EQ(m.report().duplicate_faces, 1u);
  EXPECT_NE(m.report().to_string().find("non-manifold edges: 1"), std::string::npos);
}

TEST(TriMesh, SetPositionsChecksCountAndFiniteness) {
  TriMesh m = shapes::lattice(2, 2);
  EXPECT_THROW(m.set_positions(Positions(3, Vec3::Zero())), PreconditionError);
  Positions bad = m.positions();
  bad[4].x() = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THROW(m.set_positions(bad), InputError);
}

/// Every adjacency is checked against a brute-force definition, on every mesh of the group.
TEST(Topology, AdjacenciesMatchBruteForceOnEveryMesh) {
  for (const auto& [name, mesh] : testing::small_meshes()) {
    SCOPED_TRACE(name);
    const Topology& t = mesh.topology();
    const auto row = [](const Adjacency& a, Index i) {
      return std::vector<Index>(a[i].begin(), a[i].end());
    };
    const auto shares_vertex_ff = [&](Index a, Index b) {
      for (Index u : t.face(a))
        for (Index v : t.face(b))
          if (u == v) return true;
      return false;
    };
    // Edges: unique, normalised, each side of each face maps to its edge.
    std::set<Edge> unique(t.edges().begin(), t.edges().end());
    EXPECT_EQ(unique.size(), static_cast<std::size_t>(t.num_edges()));
    for (Index f = 0; f < t.num_faces(); ++f) {
      for (int k = 0; k < 3; ++k) {
        Index a = t.face(f)[k], b = t.face(f)[(k + 1) % 3];
        const Edge e = t.edge(t.face_edges(f)[k]);
        EXPECT_EQ(e, (Edge{std::min(a, b), std::max(a, b)}));
      }
    }
    for (Index e = 0; e < t.num_edges(); ++e) {
      EXPECT_LT(t.edge(e)[0], t.edge(e)[1]);
      std::vector<Index> faces, edges;
      for (Index f = 0; f < t.num_faces(); ++f) {
        const auto& fe = t.face_edges(f);
        if (std::find(fe.begin(), fe.end(), e) != fe.end()) faces.push_back(f);
      }
      EXPECT_EQ(row(t.edge_faces(), e), faces);
      for (Index o = 0; o < t.num_edges(); ++o)
        if (o != e && t.edges_adjacent(e, o)) edges.push_back(o);
      EXPECT_EQ(row(t.edge_edges(), e), edges);
    }
    for (Index v = 0; v < t.num_vertices(); ++v) {
      std::vector<Index> edges, faces, ring;
      for (Index e = 0; e < t.num_edges(); ++e) {
        if (t.edge(e)[0] == v) ring.push_back(t.edge(e)[1]);
        if (t.edge(e)[1] == v) ring.push_back(t.edge(e)[0]);
        if (t.edge(e)[0] == v || t.edge(e)[1] == v) edges.push_back(e);
      }
      for (Index f = 0; f < t.num_faces(); ++f)
        if (t.face_has_vertex(f, v)) faces.push_back(f);
      std::sort(ring.begin(), ring.end());
      EXPECT_EQ(row(t.vertex_edges(), v), edges);
      EXPECT_EQ(row(t.vertex_faces(), v), faces);
      EXPECT_EQ(row(t.vertex_vertices(), v), ring);
    }
    for (Index f = 0; f < t.num_faces(); ++f) {
      std::vector<Index> faces;
      for (Index o = 0; o < t.num_faces(); ++o)
        if (o != f && shares_vertex_ff(f, o)) faces.push_back(o);
      EXPECT_EQ(row(t.face_faces(), f), faces);
      for (Index o = 0; o < t.num_faces(); ++o) EXPECT_EQ(t.faces_adjacent(f, o), o == f || shares_vertex_ff(f, o));
    }
  }
}

TEST(Topology, ClosedMeshesHaveNoBoundary) {
  for (const auto& [name, mesh] : testing::small_meshes()) {
    if (name != "tetrahedron" && name != "octahedron") continue;
    SCOPED_TRACE(name);
    EXPECT_EQ(mesh.report().boundary_edges, 0u);
    // Euler characteristic of a sphere.
    EXPECT_EQ(mesh.num_vertices() - mesh.num_edges() + mesh.num_faces(), 2);
  }
}

TEST(Shapes, LatticeLayoutIsAsDocumented) {
  const TriMesh m = shapes::lattice(3, 2, 3.0, 2.0);
  EXPECT_EQ(m.num_vertices(), 12);
  EXPECT_EQ(m.num_faces(), 12);
  EXPECT_EQ(m.num_edges(), 3 * 3 + 4 * 2 + 6);  // horizontal + vertical + diagonals
  EXPECT_EQ(m.positions()[5], Vec3(1, 1, 0));   // vertex (i=1, j=1)
  EXPECT_EQ(m.topology().face(0), (Face{0, 1, 5}));
  EXPECT_EQ(m.topology().face(1), (Face{0, 5, 4}));
}

TEST(Shapes, FoldedClothLayersAreCloseButNotIntersecting) {
  const shapes::FoldedClothParams params;
  const TriMesh m = shapes::folded_cloth(params);
  const Bounds b = compute_bounds(m.positions());
  EXPECT_GT(b.max.x(), 0.5);
  EXPECT_LE(b.max.x(), 0.5 + params.gap / 2 + 1e-12);
  EXPECT_GT(b.max.z(), params.gap);
  EXPECT_LT(b.max.z(), params.gap + params.wave + 1e-12);
  EXPECT_GE(b.min.z(), 0.0);
  EXPECT_EQ(m.report().zero_area_faces, 0u);
}

TEST(Mesh, BoundsAndEdgeLengths) {
  const TriMesh m = shapes::lattice(2, 1, 2.0, 1.0);
  const Bounds b = compute_bounds(m.positions());
  EXPECT_EQ(b.min, Vec3(0, 0, 0));
  EXPECT_EQ(b.max, Vec3(2, 1, 0));
  const EdgeLengthStats s = edge_length_stats(m.topology(), m.positions());
  EXPECT_DOUBLE_EQ(s.min, 1.0);
  EXPECT_DOUBLE_EQ(s.max, std::sqrt(2.0));
  // Edges of non-finite length are left out (hash's cell size is this mean).
  Positions x = m.positions();
  x[0] = Vec3(std::nan(""), 0, 0);
  const EdgeLengthStats f = edge_length_stats(m.topology(), x);
  EXPECT_DOUBLE_EQ(f.min, 1.0);
  EXPECT_DOUBLE_EQ(f.max, std::sqrt(2.0));
  EXPECT_TRUE(std::isfinite(f.mean));
  EXPECT_GT(f.mean, 1.0);
  for (Vec3& p : x) p = Vec3(std::nan(""), 0, 0);
  const EdgeLengthStats none = edge_length_stats(m.topology(), x);
  EXPECT_EQ(none.min, 0.0);
  EXPECT_EQ(none.mean, 0.0);
  EXPECT_EQ(none.max, 0.0);
}

}  // namespace
}  // namespace crumple
