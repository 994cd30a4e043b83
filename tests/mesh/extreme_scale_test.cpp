// Regression (issue 45, defect 6): with coordinates near 1e300 the squared lengths overflowed,
// so `crumple info` printed edge lengths 0, a diagonal of inf and every face as zero-area.
// Lengths, the bounds' diagonal and the zero-area test are now scale-free.
#include <crumple/mesh/mesh.hpp>
#include <crumple/mesh/shapes.hpp>

#include <gtest/gtest.h>

#include <cmath>

namespace crumple {
namespace {

TriMesh scaled_lattice(Scalar scale) {
  const TriMesh unit = shapes::lattice(4, 3, 4.0, 3.0);  // unit squares: edges 1 and sqrt(2)
  Positions x = unit.positions();
  for (Vec3& p : x) p = p * scale - Vec3::Constant(scale);  // negative corner too
  return TriMesh::create(std::move(x), {unit.topology().faces().begin(), unit.topology().faces().end()});
}

TEST(ExtremeScale, LengthsDiagonalAndAreasAreRightAt1e300And1eMinus300) {
  const TriMesh unit = scaled_lattice(1);
  const EdgeLengthStats u = edge_length_stats(unit.topology(), unit.positions());
  for (const Scalar scale : {1e300, 1e-300, 1e154, 1e-160}) {
    SCOPED_TRACE(scale);
    const TriMesh m = scaled_lattice(scale);
    const EdgeLengthStats s = edge_length_stats(m.topology(), m.positions());
    EXPECT_NEAR(s.min / scale, u.min, 1e-12);
    EXPECT_NEAR(s.max / scale, u.max, 1e-12);
    EXPECT_NEAR(s.mean / scale, u.mean, 1e-12);
    EXPECT_NEAR(compute_bounds(m.positions()).diagonal() / scale, 5.0, 1e-12);
    EXPECT_EQ(m.report().zero_area_faces, 0u);
    EXPECT_GT(default_thickness(m.positions()), 0);
    EXPECT_TRUE(std::isfinite(default_thickness(m.positions())));
  }
}

TEST(ExtremeScale, MeanOfManyHugeEdgesDoesNotOverflow) {
  // 1e308-long edges: their sum overflows, their mean does not.
  Positions x{Vec3(-0.5e308, 0, 0), Vec3(0.5e308, 0, 0), Vec3(0, 0.5e308, 0), Vec3(0, -0.5e308, 0)};
  const TriMesh m = TriMesh::create(x, {{0, 1, 2}, {0, 3, 1}});
  const EdgeLengthStats s = edge_length_stats(m.topology(), m.positions());
  EXPECT_DOUBLE_EQ(s.max, 1e308);
  EXPECT_TRUE(std::isfinite(s.mean));
  EXPECT_GT(s.mean, s.min);
  EXPECT_EQ(m.report().zero_area_faces, 0u);
}

}  // namespace
}  // namespace crumple
