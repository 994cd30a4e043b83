// Regression (issue 45, defect 7): `naive --kinds tt` ran the exact triangle test on every
// pair, 61 s on a flat 60x60 sheet where nearly all pairs are coplanar and far apart. A box
// test now skips the pairs whose bounding boxes are disjoint; the result must not change.
#include <crumple/detect/detector.hpp>
#include <crumple/geometry/triangle_intersection.hpp>
#include <crumple/mesh/shapes.hpp>

#include <gtest/gtest.h>

#include <set>
#include <utility>

namespace crumple {
namespace {

std::pair<ContactSet, double> naive_tt(const TriMesh& mesh, PositionsView x) {
  auto d = make_detector(MethodSpec(Method::Naive), {.thickness = 1e-3, .kinds = ContactKinds::parse("tt")});
  d->set_topology(mesh.topology_ptr());
  ContactSet out;
  d->update(x, out);
  return {out, d->stats().get("tt_exact_tests")};
}

TEST(NaiveTriangles, AFlatSheetNeedsFewExactTests) {
  const TriMesh sheet = shapes::lattice(30, 30);  // 1800 coplanar faces
  const auto [out, exact] = naive_tt(sheet, sheet.positions());
  EXPECT_TRUE(out.tt.empty());
  const double pairs = 1800.0 * 1799 / 2;
  EXPECT_GT(exact, 0);
  EXPECT_LT(exact, pairs / 100) << exact << " exact tests of " << pairs << " pairs";
}

TEST(NaiveTriangles, SameIntersectionsAsTheAllPairsExactTest) {
  // A sheet folded through itself: a second copy tilted across the first, in one mesh.
  const TriMesh unit = shapes::lattice(8, 8);
  Positions x = unit.positions();
  std::vector<Face> faces(unit.topology().faces().begin(), unit.topology().faces().end());
  const auto n = static_cast<Index>(x.size());
  for (Index v = 0; v < n; ++v) {
    const Vec3 p = x[static_cast<std::size_t>(v)];
    x.push_back(Vec3(p.x() + 0.03, 0.5 + 0.02 * p.y(), p.y() - 0.5));  // crosses z = 0
  }
  for (Index f = 0; f < unit.num_faces(); ++f) {
    const Face& t = unit.topology().face(f);
    faces.push_back({t[0] + n, t[1] + n, t[2] + n});
  }
  const TriMesh mesh = TriMesh::create(x, faces);
  const auto [out, exact] = naive_tt(mesh, mesh.positions());
  std::set<std::pair<Index, Index>> expected;
  const Topology& topo = mesh.topology();
  for (Index a = 0; a < topo.num_faces(); ++a) {
    for (Index b = a + 1; b < topo.num_faces(); ++b) {
      if (topo.faces_adjacent(a, b)) continue;
      const Face &s = topo.face(a), &t = topo.face(b);
      const auto at = [&](Index v) { return x[static_cast<std::size_t>(v)]; };
      if (geometry::triangles_intersect(at(s[0]), at(s[1]), at(s[2]), at(t[0]), at(t[1]), at(t[2]))) {
        expected.insert({a, b});
      }
    }
  }
  std::set<std::pair<Index, Index>> got;
  for (const auto& c : out.tt) got.insert({c.face0, c.face1});
  EXPECT_FALSE(expected.empty());
  EXPECT_EQ(got, expected);
  EXPECT_LT(exact, static_cast<double>(topo.num_faces()) * (topo.num_faces() - 1) / 2);
}

}  // namespace
}  // namespace crumple
