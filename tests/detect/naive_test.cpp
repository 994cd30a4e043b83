// The reference detector against the independent oracle (tests/support/oracle.hpp) and
// hand-made configurations with known answers.
#include <crumple/detect/detector.hpp>
#include <crumple/detect/naive.hpp>
#include <crumple/io/mesh_io.hpp>
#include <support/meshes.hpp>
#include <support/oracle.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <sstream>

namespace crumple {
namespace {

ContactSet run_naive(const TriMesh& mesh, PositionsView x, Scalar h, ContactKinds kinds = {},
                     int threads = 0) {
  auto d = make_detector(MethodSpec(Method::Naive), {.thickness = h, .kinds = kinds, .threads = threads});
  d->set_topology(mesh.topology_ptr());
  ContactSet out;
  d->update(x, out);
  return out;
}

/// Every reported contact is real and every clearly-real contact is reported. Pairs within a
/// relative 1e-9 of the thickness may go either way (the oracle uses other arithmetic).
void expect_matches_oracle(const TriMesh& mesh, PositionsView x, Scalar h, const ContactSet& got) {
  const Topology& t = mesh.topology();
  const auto oracle = oracle::brute_force(t, x, h * (1 + 1e-9));
  const long double hi = h * (1 + 1e-9), lo = h * (1 - 1e-9);
  std::size_t vf_clear = 0, ee_clear = 0;
  for (const auto& [k, d] : oracle.vf) vf_clear += d < lo;
  for (const auto& [k, d] : oracle.ee) ee_clear += d < lo;
  std::size_t vf_found = 0, ee_found = 0;
  for (const auto& c : got.vf) {
    auto it = oracle.vf.find({c.vertex, c.face});
    ASSERT_NE(it, oracle.vf.end()) << "false VF contact " << c.vertex << " " << c.face << " d=" << c.distance;
    EXPECT_NEAR(c.distance, static_cast<double>(it->second), 1e-9 * h + 1e-12 * x.size());
    ASSERT_LT(c.distance, h);
    vf_found += it->second < lo;
  }
  for (const auto& c : got.ee) {
    auto it = oracle.ee.find({c.a[0], c.a[1], c.b[0], c.b[1]});
    ASSERT_NE(it, oracle.ee.end()) << "false EE contact " << c.a[0] << "-" << c.a[1] << " "
                                   << c.b[0] << "-" << c.b[1] << " d=" << c.distance;
    EXPECT_NEAR(c.distance, static_cast<double>(it->second), 1e-9 * h);
    ee_found += it->second < lo;
  }
  EXPECT_EQ(vf_found, vf_clear) << "VF contacts missed";
  EXPECT_EQ(ee_found, ee_clear) << "EE contacts missed";
  (void)hi;
}

/// Contact fields are consistent with the geometry: barycentrics reproduce the distance,
/// s/t reproduce the distance, normals are unit and point from face/edge a to vertex/edge b.
void expect_contacts_well_formed(const TriMesh& mesh, PositionsView x, const ContactSet& got) {
  const Topology& t = mesh.topology();
  const auto X = [&](Index i) { return x[static_cast<std::size_t>(i)]; };
  for (const auto& c : got.vf) {
    EXPECT_FALSE(t.face_has_vertex(c.face, c.vertex));
    const Face& f = t.face(c.face);
    const Vec3 q = c.barycentric[0] * X(f[0]) + c.barycentric[1] * X(f[1]) + c.barycentric[2] * X(f[2]);
    EXPECT_NEAR((X(c.vertex) - q).norm(), c.distance, 1e-9);
    EXPECT_NEAR(c.barycentric.sum(), 1.0, 1e-12);
    EXPECT_GE(c.barycentric.minCoeff(), 0.0);
    if (c.distance > 1e-9) {
      EXPECT_NEAR(c.normal.norm(), 1.0, 1e-12);
      EXPECT_NEAR((q + c.distance * c.normal - X(c.vertex)).norm(), 0.0, 1e-9);
    }
  }
  for (const auto& c : got.ee) {
    EXPECT_LT(c.a[0], c.a[1]);
    EXPECT_LT(c.b[0], c.b[1]);
    EXPECT_LT(c.a, c.b);
    EXPECT_EQ(t.edge(c.edge0), c.a);
    EXPECT_EQ(t.edge(c.edge1), c.b);
    EXPECT_FALSE(t.edges_adjacent(c.edge0, c.edge1));
    const Vec3 p = (1 - c.s) * X(c.a[0]) + c.s * X(c.a[1]);
    const Vec3 q = (1 - c.t) * X(c.b[0]) + c.t * X(c.b[1]);
    EXPECT_NEAR((p - q).norm(), c.distance, 1e-9);
    if (c.distance > 1e-9) {
      EXPECT_NEAR((p + c.distance * c.normal - q).norm(), 0.0, 1e-9);
    }
  }
}

TEST(Naive, HandMadeVertexOverFace) {
  // A triangle in z = 0 and a second, far triangle whose corner 3 hovers 0.05 over the first.
  const TriMesh m = TriMesh::create({Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0), Vec3(0.25, 0.25, 0.05),
                                     Vec3(2, 2, 1), Vec3(2, 3, 1)},
                                    {{0, 1, 2}, {3, 4, 5}});
  const ContactSet c = run_naive(m, m.positions(), 0.1);
  ASSERT_EQ(c.vf.size(), 1u);
  EXPECT_EQ(c.vf[0].vertex, 3);
  EXPECT_EQ(c.vf[0].face, 0);
  EXPECT_NEAR(c.vf[0].distance, 0.05, 1e-15);
  EXPECT_NEAR((c.vf[0].barycentric - Vec3(0.5, 0.25, 0.25)).norm(), 0, 1e-15);
  EXPECT_NEAR((c.vf[0].normal - Vec3(0, 0, 1)).norm(), 0, 1e-15);
  // Edges (3,4) and (3,5) reach below 0.1 of edges (0,1)? No: vertex 3 is 0.25 from them.
  EXPECT_TRUE(c.ee.empty());
  EXPECT_TRUE(run_naive(m, m.positions(), 0.05).vf.empty()) << "distance == h is not a contact";
}

TEST(Naive, HandMadeCrossingEdges) {
  // Two triangles whose edges (0,1) and (3,4) cross at distance 0.02 in z.
  const TriMesh m = TriMesh::create({Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0.5, -1, 0),
                                     Vec3(0.5, -0.5, 0.02), Vec3(0.5, 0.5, 0.02), Vec3(0.5, 0, 1)},
                                    {{0, 1, 2}, {3, 4, 5}});
  const ContactSet c = run_naive(m, m.positions(), 0.03, ContactKinds::parse("ee"));
  ASSERT_EQ(c.ee.size(), 1u);
  EXPECT_EQ(c.ee[0].a, (Edge{0, 1}));
  EXPECT_EQ(c.ee[0].b, (Edge{3, 4}));
  EXPECT_NEAR(c.ee[0].distance, 0.02, 1e-15);
  EXPECT_NEAR(c.ee[0].s, 0.5, 1e-12);
  EXPECT_NEAR(c.ee[0].t, 0.5, 1e-12);
  EXPECT_NEAR((c.ee[0].normal - Vec3(0, 0, 1)).norm(), 0, 1e-12);
  EXPECT_TRUE(c.vf.empty());
}

TEST(Naive, TriangleIntersectionOnRequest) {
  // Triangle 1 pierces triangle 0; they share no vertex.
  const TriMesh m = TriMesh::create({Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0), Vec3(0.2, 0.2, -1),
                                     Vec3(0.3, 0.2, 1), Vec3(0.2, 0.3, 1)},
                                    {{0, 1, 2}, {3, 4, 5}});
  ContactSet c = run_naive(m, m.positions(), 0.0, ContactKinds::parse("tt"));
  ASSERT_EQ(c.tt.size(), 1u);
  EXPECT_EQ(c.tt[0].face0, 0);
  EXPECT_EQ(c.tt[0].face1, 1);
  c = run_naive(m, m.positions(), 0.0, ContactKinds::parse("vf,ee"));
  EXPECT_TRUE(c.empty()) << "thickness 0 gives no proximity contact";
}

TEST(Naive, MatchesOracleOnMeshGroupAndRandomDeformations) {
  for (const auto& [name, mesh] : testing::small_meshes()) {
    for (std::uint64_t seed : {1u, 2u, 3u}) {
      SCOPED_TRACE(name + " seed " + std::to_string(seed));
      const EdgeLengthStats e = edge_length_stats(mesh.topology(), mesh.positions());
      const Positions x = testing::jitter(mesh.positions(), 0.3 * e.mean, seed);
      for (double rel : {0.1, 0.5}) {
        const ContactSet c = run_naive(mesh, x, rel * e.mean);
        expect_matches_oracle(mesh, x, rel * e.mean, c);
        expect_contacts_well_formed(mesh, x, c);
      }
    }
  }
}

TEST(Naive, MatchesOracleOnCrumpledLattices) {
  const TriMesh lattice = shapes::lattice(24, 24);
  std::size_t total = 0;
  for (std::uint64_t seed = 10; seed < 14; ++seed) {
    SCOPED_TRACE("seed " + std::to_string(seed));
    const Positions x = testing::crumple_lattice(lattice, 0.15, seed);
    const ContactSet c = run_naive(lattice, x, 0.03);
    expect_matches_oracle(lattice, x, 0.03, c);
    expect_contacts_well_formed(lattice, x, c);
    total += c.size();
  }
  EXPECT_GT(total, 100u) << "the crumpled lattices should produce contacts";
}

TEST(Naive, FoldedClothHasBothKindsAndIsThreadIndependent) {
  const shapes::FoldedClothParams params{.n = 20};
  const TriMesh m = shapes::folded_cloth(params);
  const ContactSet one = run_naive(m, m.positions(), params.thickness, {}, 1);
  const ContactSet two = run_naive(m, m.positions(), params.thickness, {}, 2);
  EXPECT_GT(one.vf.size(), 10u);
  EXPECT_GT(one.ee.size(), 10u);
  std::ostringstream a, b;
  write_contacts(a, one);
  write_contacts(b, two);
  EXPECT_EQ(a.str(), b.str());
  expect_matches_oracle(m, m.positions(), params.thickness, one);
}

TEST(Naive, RealThickClothBothFrames) {
  for (const char* frame : {"ipc-toolkit-tests/thick-cloth/t0.ply", "ipc-toolkit-tests/thick-cloth/t1.ply"}) {
    SCOPED_TRACE(frame);
    const TriMesh m = io::read_mesh(testing::data_path(frame));
    const Scalar diag = compute_bounds(m.positions()).diagonal();
    for (double rel : {1e-3, 1e-2}) {
      const ContactSet c = run_naive(m, m.positions(), rel * diag);
      expect_matches_oracle(m, m.positions(), rel * diag, c);
      expect_contacts_well_formed(m, m.positions(), c);
    }
  }
}

TEST(Naive, TwoCubesOnlyTheIntersectingOnesIntersect) {
  for (const char* name : {"far", "close", "intersecting"}) {
    SCOPED_TRACE(name);
    const TriMesh m = io::read_mesh(testing::data_path(std::string("ipc-toolkit-tests/two-cubes-") + name + ".ply"));
    const Scalar h = 1e-2 * compute_bounds(m.positions()).diagonal();
    const ContactSet c = run_naive(m, m.positions(), h, ContactKinds::parse("vf,ee,tt"));
    expect_matches_oracle(m, m.positions(), h, c);
    expect_contacts_well_formed(m, m.positions(), c);
    EXPECT_EQ(c.tt.empty(), std::string(name) != "intersecting");
  }
}

}  // namespace
}  // namespace crumple
