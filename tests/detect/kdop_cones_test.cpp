// Normal-cone culling in the kdop detector (`cones=on`, intersection-only queries): it must
// skip the self-tests of patches that cannot intersect themselves — and never lose an
// intersection. Checked against naive on adversarial surfaces (a helical ramp whose turns cut
// through each other with every normal facing up, two stacked sheets, a crumpled sheet, a
// flipped face) and on the real meshes.
#include <crumple/detect/broad_phase/kdop_tree.hpp>
#include <crumple/io/mesh_io.hpp>
#include <crumple/mesh/shapes.hpp>
#include <support/meshes.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <string>
#include <vector>

namespace crumple {
namespace {

const ContactKinds kTT = ContactKinds::parse("tt");

struct Outcome {
  ContactSet contacts;
  double culled = 0;
  double candidates = 0;
  double tasks = 0;  ///< traversal tasks (0 when the root's self-test is skipped)
};

Outcome run(const std::string& spec, const TriMesh& mesh, PositionsView x, ContactKinds kinds = kTT,
            Scalar h = 0.01) {
  auto d = make_detector(MethodSpec::parse(spec), {.thickness = h, .kinds = kinds});
  d->set_topology(mesh.topology_ptr());
  Outcome r;
  d->update(x, r.contacts);
  r.culled = d->stats().get("culled_nodes");
  r.candidates = d->stats().get("candidates");
  r.tasks = d->stats().get("tasks");
  return r;
}

/// The TT pairs of `got` are exactly naive's.
void expect_same_intersections(const TriMesh& mesh, PositionsView x, const Outcome& got) {
  const ContactSet want = run("naive", mesh, x).contacts;
  ASSERT_EQ(got.contacts.tt.size(), want.tt.size());
  for (std::size_t i = 0; i < want.tt.size(); ++i) {
    EXPECT_EQ(got.contacts.tt[i].face0, want.tt[i].face0);
    EXPECT_EQ(got.contacts.tt[i].face1, want.tt[i].face1);
  }
}

/// A strip wound 1.25 turns around the z axis (radius 1 to 2), its height a hump that is 0 at
/// both ends: the first and last quarter turns lie over each other at different heights at one
/// end and swap at the other, so they cut through each other. Every normal has the same sign
/// along z (the strip is a graph over its parameters, winding once around the axis locally).
TriMesh helical_ramp(Index n_turn, Index n_radial) {
  const Scalar span = 2.5 * std::numbers::pi;
  const TriMesh flat = shapes::lattice(n_turn, n_radial, span, 1.0);
  Positions x = flat.positions();
  for (Vec3& p : x) {
    const Scalar theta = p.x(), r = 1 + p.y(), t = theta / span;
    p = Vec3(r * std::cos(theta), r * std::sin(theta), 2.0 * t * (1 - t));
  }
  return TriMesh::create(std::move(x), std::vector<Face>(flat.topology().faces().begin(), flat.topology().faces().end()));
}

TEST(KdopCones, FlatSheetIsCulledWhole) {
  const TriMesh m = shapes::lattice(20, 20);
  const Outcome on = run("kdop:cones=on", m, m.positions());
  EXPECT_EQ(on.culled, 1.0) << "the root passes, nothing below it is visited";
  EXPECT_EQ(on.tasks, 0.0);
  EXPECT_TRUE(on.contacts.tt.empty());
  const Outcome off = run("kdop:cones=off", m, m.positions());
  EXPECT_EQ(off.culled, 0.0);
  EXPECT_GT(off.tasks, 0.0);
}

TEST(KdopCones, HelicalRampThatCutsItselfKeepsEveryIntersection) {
  const TriMesh m = helical_ramp(90, 4);
  // Every face normal points the same way along z: the normals test alone would cull the root.
  int up = 0, down = 0;
  for (const Face& f : m.topology().faces()) {
    const Vec3 n = (m.positions()[f[1]] - m.positions()[f[0]]).cross(m.positions()[f[2]] - m.positions()[f[0]]);
    (n.z() > 0 ? up : down)++;
  }
  ASSERT_TRUE(up == 0 || down == 0) << up << " up, " << down << " down";
  // With leaves of at most 16 faces some nodes of this small mesh pass the culling tests (with
  // the default leaf size none does); the default is checked for exactness below.
  const Outcome on = run("kdop:cones=on,leaf=16", m, m.positions());
  EXPECT_GT(on.contacts.tt.size(), 10u) << "the turns must cut through each other";
  EXPECT_GT(on.culled, 0.0) << "parts of less than a turn are still culled";
  expect_same_intersections(m, m.positions(), on);
  for (const char* spec : {"kdop:cones=on", "kdop:cones=on,k=6,arity=2,leaf=1", "kdop:cones=on,k=26,arity=8,leaf=16"}) {
    SCOPED_TRACE(spec);
    expect_same_intersections(m, m.positions(), run(spec, m, m.positions()));
  }
}

TEST(KdopCones, StackedSheetsCrossingEachOther) {
  // Two separate 10x10 sheets, normals up, the second tilted through the first.
  const TriMesh a = shapes::lattice(10, 10);
  Positions x = a.positions();
  std::vector<Face> faces(a.topology().faces().begin(), a.topology().faces().end());
  const Index nv = static_cast<Index>(x.size());
  for (const Vec3& p : a.positions()) x.push_back(Vec3(p.x() + 0.05, p.y() + 0.03, 0.2 * (p.x() - 0.5)));
  for (const Face& f : a.topology().faces()) faces.push_back({f[0] + nv, f[1] + nv, f[2] + nv});
  const TriMesh m = TriMesh::create(x, faces);
  const Outcome on = run("kdop:cones=on", m, m.positions());
  EXPECT_GT(on.contacts.tt.size(), 5u);
  expect_same_intersections(m, m.positions(), on);
}

TEST(KdopCones, CrumpledSheetsAndAFlippedFace) {
  const TriMesh lattice = shapes::lattice(24, 24);
  for (std::uint64_t seed : {3u, 4u, 5u}) {
    for (double amplitude : {0.05, 0.2, 0.4}) {
      const Positions x = testing::crumple_lattice(lattice, amplitude, seed);
      SCOPED_TRACE(amplitude);
      expect_same_intersections(lattice, x, run("kdop:cones=on", lattice, x));
    }
  }
  // One face wound the other way: the nodes holding it are not consistently oriented.
  std::vector<Face> faces(lattice.topology().faces().begin(), lattice.topology().faces().end());
  std::swap(faces[100][1], faces[100][2]);
  const TriMesh flipped = TriMesh::create(lattice.positions(), faces);
  const Positions x = testing::crumple_lattice(flipped, 0.3, 7);
  expect_same_intersections(flipped, x, run("kdop:cones=on", flipped, x));
}

TEST(KdopCones, ProximityQueriesAreNeverCulled) {
  const TriMesh m = shapes::lattice(20, 20);
  // h = 0.1 > the lattice's closest non-adjacent distance (0.035): proximity pairs exist
  // inside a flat sheet, which a cone test would wrongly skip.
  const Outcome r = run("kdop:cones=on", m, m.positions(), ContactKinds::parse("vf,ee,tt"), 0.1);
  EXPECT_EQ(r.culled, 0.0);
  EXPECT_GT(r.contacts.vf.size() + r.contacts.ee.size(), 100u);
  const Outcome naive = run("naive", m, m.positions(), ContactKinds::parse("vf,ee,tt"), 0.1);
  EXPECT_EQ(r.contacts.size(), naive.contacts.size());
}

TEST(KdopCones, RealMeshesSameIntersectionsAsWithoutCones) {
  // kdop without cones is checked against naive on these frames (exact_detectors_test.cpp).
  for (const char* file : {"sample-scalable-ccd/cloth-funnel/frames/228.ply",
                           "sample-scalable-ccd/armadillo-rollers/frames/327.ply",
                           "ipc-toolkit-tests/two-cubes-intersecting.ply", "ipc-toolkit-tests/bunny.ply"}) {
    SCOPED_TRACE(file);
    const TriMesh m = io::read_mesh(testing::data_path(file));
    const Outcome on = run("kdop:cones=on", m, m.positions()), off = run("kdop:cones=off", m, m.positions());
    ASSERT_EQ(on.contacts.tt.size(), off.contacts.tt.size());
    for (std::size_t i = 0; i < on.contacts.tt.size(); ++i) {
      EXPECT_EQ(on.contacts.tt[i].face0, off.contacts.tt[i].face0);
      EXPECT_EQ(on.contacts.tt[i].face1, off.contacts.tt[i].face1);
    }
  }
}

}  // namespace
}  // namespace crumple
