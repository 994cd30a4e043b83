// The reference's box cull (`naive:cull=on`, the default) against its plain loop
// (`naive:cull=off`, every pair through the exact test): the same contacts bit for bit,
// including pairs a rounding away from the thickness and far from the origin, with far fewer
// exact tests.
#include <crumple/detect/detector.hpp>
#include <crumple/detect/contact.hpp>
#include <crumple/mesh/shapes.hpp>
#include <support/meshes.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <exception>
#include <limits>
#include <sstream>
#include <string>

namespace crumple {
namespace {

struct Outcome {
  std::string contacts;  // write_contacts: the pairs and their distances, round-tripping
  std::size_t size = 0;
  double vf_exact = 0, ee_exact = 0, tt_exact = 0;
};

Outcome run(const std::string& spec, const TriMesh& mesh, PositionsView x, Scalar h, int threads = 2) {
  auto d = make_detector(MethodSpec::parse(spec),
                         {.thickness = h, .kinds = ContactKinds::parse("vf,ee,tt"), .threads = threads});
  d->set_topology(mesh.topology_ptr());
  ContactSet out;
  d->update(x, out);
  std::ostringstream text;
  write_contacts(text, out);
  return {text.str(), out.size(), d->stats().get("vf_exact_tests"), d->stats().get("ee_exact_tests"),
          d->stats().get("tt_exact_tests")};
}

/// Same contacts with and without the cull; returns the culled run.
Outcome expect_cull_changes_nothing(const TriMesh& mesh, PositionsView x, Scalar h) {
  const Outcome plain = run("naive:cull=off", mesh, x, h);
  const Outcome culled = run("naive", mesh, x, h, 1);
  EXPECT_EQ(culled.contacts, plain.contacts);
  EXPECT_EQ(run("naive:cull=on", mesh, x, h, 3).contacts, plain.contacts) << "thread count";
  return culled;
}

TEST(NaiveCull, SameContactsOnSmallAndCrumpledMeshes) {
  for (const auto& [name, mesh] : testing::small_meshes()) {
    SCOPED_TRACE(name);
    const EdgeLengthStats e = edge_length_stats(mesh.topology(), mesh.positions());
    const Positions x = testing::jitter(mesh.positions(), 0.3 * e.mean, 7);
    for (double rel : {0.0, 0.1, 0.5, 3.0}) expect_cull_changes_nothing(mesh, x, rel * e.mean);
  }
  const TriMesh lattice = shapes::lattice(16, 16);
  const Positions x = testing::crumple_lattice(lattice, 0.15, 11);
  const Outcome r = expect_cull_changes_nothing(lattice, x, 0.03);
  EXPECT_GT(r.size, 100u);
  const double vertices = 289, faces = 512, edges = 800;
  EXPECT_LT(r.vf_exact, vertices * faces / 10) << "the cull should spare most vertex-face tests";
  EXPECT_LT(r.ee_exact, edges * edges / 20) << "the cull should spare most edge-edge tests";
  EXPECT_EQ(run("naive:cull=off", lattice, x, 0.03).vf_exact, vertices * faces - 3 * faces);
}

TEST(NaiveCull, SameContactsAtARoundingFromTheThicknessFarFromTheOrigin) {
  // Two parallel sheets h apart give pairs whose distance is h to within a rounding: the cull
  // must leave each to the exact test. Far from the origin (1e8) the coordinates' rounding
  // dwarfs the nudges; a tilt makes the gaps differ along the sheet.
  const TriMesh sheet = shapes::lattice(6, 6);
  for (double offset : {0.0, 1e8}) {
    for (double h : {1e-3, 0.05}) {
      for (double nudge : {-2e-16, 2e-16}) {
        SCOPED_TRACE("offset " + std::to_string(offset) + " h " + std::to_string(h) + " nudge " + std::to_string(nudge));
        Positions x;
        std::vector<Face> faces;
        const auto nv = static_cast<Index>(sheet.positions().size());
        for (int layer = 0; layer < 2; ++layer) {
          for (const Vec3& p : sheet.positions()) {
            const double z = layer * h * (1 + nudge) * (1 + 1e-7 * p.x());
            x.push_back(Vec3(p.x() + offset + 0.01 * layer, p.y() + offset, z + offset));
          }
          for (const Face& f : sheet.topology().faces()) faces.push_back({f[0] + layer * nv, f[1] + layer * nv, f[2] + layer * nv});
        }
        const TriMesh two = TriMesh::create(x, faces);
        expect_cull_changes_nothing(two, two.positions(), h);
      }
    }
  }
}

TEST(NaiveCull, SameContactsWithCoordinatesThatAreNotFinite) {
  // A vertex at infinity: its features are never culled and the exact test decides.
  const TriMesh lattice = shapes::lattice(6, 6);
  Positions x = testing::crumple_lattice(lattice, 0.15, 3);
  x[10].x() = std::numeric_limits<double>::infinity();
  const auto plain = [&] {
    try {
      return run("naive:cull=off", lattice, x, 0.05).contacts;
    } catch (const std::exception& e) {
      return std::string("error: ") + e.what();
    }
  }();
  const auto culled = [&] {
    try {
      return run("naive", lattice, x, 0.05).contacts;
    } catch (const std::exception& e) {
      return std::string("error: ") + e.what();
    }
  }();
  EXPECT_EQ(culled, plain);
}

}  // namespace
}  // namespace crumple
