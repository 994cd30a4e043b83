// Flat neighbours (`drop_flat_neighbours`): the detected pairs of one flat patch of the cloth
// leave the proximity response; pairs of two layers, and of two separate sheets, stay.
#include <crumple/detect/detector.hpp>
#include <crumple/mesh/shapes.hpp>
#include <crumple/response/contact_response.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <set>
#include <vector>

namespace crumple::response {
namespace {

/// Every VF and EE pair of `mesh` within `radius`, by the naive (exact, all pairs) detector.
std::vector<Stencil> pairs_within(const TriMesh& mesh, Scalar radius) {
  auto detector = make_detector(MethodSpec::parse("naive"), {.thickness = radius, .threads = 1});
  detector->set_topology(mesh.topology_ptr());
  ContactSet contacts;
  detector->update(mesh.positions(), contacts);
  return make_stencils(contacts, mesh.topology().faces());
}

// The proximity radius of `crumple:n=200` (4 h_c = 1.2 edges) takes in the flat cloth's own
// neighbours; all of them are flat neighbours.
TEST(FlatNeighbours, FlatLatticeWithinTheRadiusIsAllFlatNeighbours) {
  const Index n = 12;
  const TriMesh mesh = shapes::lattice(n, n);
  const Scalar edge = 1.0 / n;
  std::vector<Stencil> stencils = pairs_within(mesh, 1.2 * edge);
  const std::size_t found = stencils.size();
  ASSERT_GT(found, 500u) << "the lattice's own neighbours fall within 1.2 edges";
  EXPECT_EQ(drop_flat_neighbours(stencils, mesh.topology(), mesh.positions()), found);
  EXPECT_TRUE(stencils.empty());
}

// The lattice folded over itself: the pairs between the two layers (normal across the layers)
// all stay, also those within two rings around the fold; the flat lower layer's own pairs go.
TEST(FlatNeighbours, PairsBetweenLayersStay) {
  shapes::FoldedClothParams params;
  params.n = 16;
  params.gap = 0.02;
  const TriMesh mesh = shapes::folded_cloth(params);
  const auto& x = mesh.positions();
  const Scalar edge = 1.0 / params.n;
  const std::vector<Stencil> all = pairs_within(mesh, 1.2 * edge);
  std::vector<Stencil> kept = all;
  const std::size_t dropped = drop_flat_neighbours(kept, mesh.topology(), x);
  EXPECT_GT(dropped, 0u);
  const auto key = [](const Stencil& s) { return std::make_pair(s.edge_edge, s.vertex); };
  std::set<std::pair<bool, std::array<Index, 4>>> left;
  for (const Stencil& s : kept) left.insert(key(s));
  std::size_t across = 0, lower = 0;
  for (const Stencil& s : all) {
    const std::size_t split = s.edge_edge ? 2 : 1;
    const auto at = [&](std::size_t k) { return x[static_cast<std::size_t>(s.vertex[k])]; };
    Scalar za = 0, zb = 0;  // the highest vertex of each side
    bool flat_lower = true;  // all four on the lower layer, away from the fold
    for (std::size_t k = 0; k < 4; ++k) {
      Scalar& z = k < split ? za : zb;
      z = std::max(z, at(k).z());
      flat_lower &= at(k).z() == 0 && at(k).x() < 0.45;
    }
    // Two layers: one side on the lower layer (z = 0), the other above it by half the gap.
    const bool two_layers = std::min(za, zb) == 0 && std::abs(za - zb) > 0.5 * params.gap;
    if (two_layers && std::abs(s.normal.z()) > 0.9) {
      ++across;
      EXPECT_TRUE(left.count(key(s))) << "a pair between the layers was dropped";
    }
    if (flat_lower) {
      ++lower;
      EXPECT_FALSE(left.count(key(s))) << "a pair of the flat lower layer was kept";
    }
  }
  EXPECT_GT(across, 100u);
  EXPECT_GT(lower, 100u);
}

// Two lattices side by side in one plane, 0.3 edges apart: the pairs across the seam are flat
// and face alike but belong to two sheets (no path of two edges joins them): they stay.
TEST(FlatNeighbours, SeparateSheetsInOnePlaneStay) {
  const Index n = 6;
  const Scalar edge = 1.0 / n;
  const TriMesh a = shapes::lattice(n, n);
  std::vector<Vec3> x = a.positions();
  std::vector<Face> faces(a.topology().faces().begin(), a.topology().faces().end());
  const Index offset = static_cast<Index>(x.size());
  for (const Vec3& p : a.positions()) x.push_back(p + Vec3(1 + 0.3 * edge, 0, 0));
  for (const Face& f : a.topology().faces()) faces.push_back({f[0] + offset, f[1] + offset, f[2] + offset});
  const TriMesh mesh = TriMesh::create(x, faces);
  std::vector<Stencil> stencils = pairs_within(mesh, 1.2 * edge);
  std::size_t seam = 0;
  for (const Stencil& s : stencils) seam += (s.vertex[0] < offset) != (s.vertex[3] < offset) ? 1 : 0;
  ASSERT_GT(seam, 0u);
  drop_flat_neighbours(stencils, mesh.topology(), mesh.positions());
  EXPECT_EQ(stencils.size(), seam) << "exactly the seam's pairs are left";
  for (const Stencil& s : stencils) EXPECT_NE(s.vertex[0] < offset, s.vertex[3] < offset);
}

}  // namespace
}  // namespace crumple::response
