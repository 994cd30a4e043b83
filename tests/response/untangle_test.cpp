// Global Intersection Analysis on handcrafted sheets (a closed loop, a flap through a sheet, a
// slit), and the untangler's pushes alone: the intersections go to 0.
#include <crumple/core/error.hpp>
#include <crumple/detect/detector.hpp>
#include <crumple/geometry/triangle_intersection.hpp>
#include <crumple/response/untangle.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>

#include "support/intersections.hpp"

namespace crumple::response {
namespace {

/// Sheets of lattice quads (two triangles each) collected into one mesh.
struct Sheets {
  Positions x;
  std::vector<Face> faces;
  /// Appends an nx × nz lattice, vertex (i, j) at `position(i, j)`; returns its first id.
  Index add(Index nx, Index nz, const std::function<Vec3(Index, Index)>& position) {
    const Index first = static_cast<Index>(x.size());
    for (Index j = 0; j <= nz; ++j) {
      for (Index i = 0; i <= nx; ++i) x.push_back(position(i, j));
    }
    const auto id = [&](Index i, Index j) { return first + j * (nx + 1) + i; };
    for (Index j = 0; j < nz; ++j) {
      for (Index i = 0; i < nx; ++i) {
        faces.push_back({id(i, j), id(i + 1, j), id(i + 1, j + 1)});
        faces.push_back({id(i, j), id(i + 1, j + 1), id(i, j + 1)});
      }
    }
    return first;
  }
  std::shared_ptr<const Topology> topology() const {
    return std::make_shared<const Topology>(Topology::build(static_cast<Index>(x.size()), faces));
  }
};

/// Sheet A (4 × 4 quads over the unit square at y = 0.1, ids 0..24) has its centre vertex 12
/// pushed down to y = -0.3, through sheet B (10 × 10 quads at y = 0, shifted off A's lattice):
/// one closed intersection curve around the bump.
Sheets bump() {
  Sheets s;
  s.add(4, 4, [](Index i, Index j) { return Vec3(i * 0.25, i == 2 && j == 2 ? -0.3 : 0.1, j * 0.25); });
  s.add(10, 10, [](Index i, Index j) { return Vec3(i * 0.1 - 0.013, 0, j * 0.1 - 0.017); });
  return s;
}

/// Vertices of sheet B (from `first`) that sheet A passes below: the vertical segment from the
/// vertex down by 1 meets one of A's faces (the first `a_faces` faces). An oracle independent
/// of the flood fill.
std::vector<Index> below_a(const Sheets& s, Index first, std::size_t a_faces) {
  std::vector<Index> out;
  for (Index v = first; v < static_cast<Index>(s.x.size()); ++v) {
    const Vec3& p = s.x[static_cast<std::size_t>(v)];
    for (std::size_t f = 0; f < a_faces; ++f) {
      const Face& t = s.faces[f];
      if (geometry::segment_triangle_intersect(p, p - Vec3(0, 1, 0), s.x[static_cast<std::size_t>(t[0])],
                                               s.x[static_cast<std::size_t>(t[1])], s.x[static_cast<std::size_t>(t[2])])) {
        out.push_back(v);
        break;
      }
    }
  }
  return out;
}

TEST(Untangle, ClosedLoopFindsBothInsideRegions) {
  const Sheets s = bump();
  const auto topology = s.topology();
  const auto pairs = testing::intersecting_triangles(topology, s.x);
  ASSERT_GT(pairs.size(), 0u);
  const IntersectionAnalysis a = analyse_intersections(*topology, s.x, pairs);
  EXPECT_EQ(a.pairs, pairs.size());
  ASSERT_EQ(a.contours.size(), 1u) << "one curve around the bump";
  const Contour& k = a.contours[0];
  EXPECT_FALSE(k.open);
  EXPECT_EQ(k.pairs, pairs.size());
  EXPECT_EQ(k.crossings.size(), a.crossings.size());
  EXPECT_EQ(k.parts, 4u) << "each sheet cut in two";
  // Every edge of A's centre vertex crosses B.
  for (Index e : topology->vertex_edges()[12]) {
    EXPECT_TRUE(std::any_of(a.crossings.begin(), a.crossings.end(), [&](const Crossing& c) { return c.edge == e; }))
        << "edge " << e;
  }
  // Inside: A's centre, and the part of B that the bump encloses.
  std::vector<Index> expected = below_a(s, 25, 32);
  ASSERT_GT(expected.size(), 0u);
  EXPECT_LT(expected.size(), 60u);
  expected.insert(expected.begin(), 12);
  EXPECT_EQ(k.inside, expected);
  EXPECT_EQ(a.inside_vertices, expected.size());
  // The tangle: the inside and the corners of the intersecting faces.
  for (Index v : expected) EXPECT_TRUE(a.tangle[static_cast<std::size_t>(v)]) << v;
  EXPECT_FALSE(a.tangle[0]) << "A's corner is far from the bump";
}

/// Sheet B (ids 0..120) at y = 0 over the unit square; sheet A (6 × 6 quads over [0.2, 0.8]²)
/// slopes down along x and passes through B at x = 0.64: its two columns x = 0.7, 0.8 are a
/// flap below B, and the curve runs from A's border to A's border.
Sheets flap() {
  Sheets s;
  s.add(10, 10, [](Index i, Index j) { return Vec3(i * 0.1 - 0.013, 0, j * 0.1 - 0.017); });
  s.add(6, 6, [](Index i, Index j) {
    const Scalar x = 0.2 + i * 0.1;
    return Vec3(x, 0.22 - 0.5 * (x - 0.2), 0.2 + j * 0.1);
  });
  return s;
}

TEST(Untangle, FlapThroughASheetIsTheInsideOfAnOpenCurve) {
  Sheets s = flap();
  const auto topology = s.topology();
  const auto pairs = testing::intersecting_triangles(topology, s.x);
  ASSERT_GT(pairs.size(), 0u);
  const IntersectionAnalysis a = analyse_intersections(*topology, s.x, pairs);
  ASSERT_EQ(a.contours.size(), 1u);
  const Contour& k = a.contours[0];
  EXPECT_TRUE(k.open) << "the curve reaches A's border";
  EXPECT_EQ(k.parts, 3u) << "A cut in two, B not cut off";
  std::vector<Index> expected;  // A's vertices below B
  for (Index v = 121; v < static_cast<Index>(s.x.size()); ++v) {
    if (s.x[static_cast<std::size_t>(v)].y() < 0) expected.push_back(v);
  }
  ASSERT_EQ(expected.size(), 14u);
  EXPECT_EQ(k.inside, expected);

  // A pinned vertex in the flap: the flap cannot go back through, so the rest of A is the inside.
  std::vector<Scalar> inv_mass(s.x.size(), 1);
  inv_mass[static_cast<std::size_t>(expected[0])] = 0;
  const IntersectionAnalysis pinned = analyse_intersections(*topology, s.x, pairs, inv_mass);
  ASSERT_EQ(pinned.contours.size(), 1u);
  EXPECT_EQ(pinned.contours[0].inside.size(), 49u - 14u);
  for (Index v : pinned.contours[0].inside) EXPECT_GE(s.x[static_cast<std::size_t>(v)].y(), 0) << v;
}

/// Sheet A at y = 0 over the unit square; sheet B upright in the plane x = 0.5 (z from 0.5 to
/// 1.5, y from -0.5 to 0.5), jittered off A's lattice: the curve runs from B's border (inside A)
/// to A's border (inside B) and cuts nothing off.
Sheets slit() {
  Sheets s;
  s.add(6, 6, [](Index i, Index j) { return Vec3(i / 6.0, 0, j / 6.0); });
  s.add(6, 6, [](Index i, Index j) { return Vec3(0.51, -0.5 + i / 6.0 + 0.013, 0.5 + j / 6.0 + 0.021); });
  return s;
}

TEST(Untangle, SlitHasNoInside) {
  const Sheets s = slit();
  const auto topology = s.topology();
  const auto pairs = testing::intersecting_triangles(topology, s.x);
  ASSERT_GT(pairs.size(), 0u);
  const IntersectionAnalysis a = analyse_intersections(*topology, s.x, pairs);
  ASSERT_EQ(a.contours.size(), 1u);
  EXPECT_TRUE(a.contours[0].open);
  EXPECT_EQ(a.contours[0].parts, 2u) << "the two sheets, nothing cut off";
  EXPECT_TRUE(a.contours[0].inside.empty());
  EXPECT_EQ(a.inside_vertices, 0u);
}

TEST(Untangle, CleanMeshHasNothing) {
  Sheets s = bump();
  s.x[12].y() = 0.05;
  const auto topology = s.topology();
  const auto pairs = testing::intersecting_triangles(topology, s.x);
  ASSERT_EQ(pairs.size(), 0u);
  const IntersectionAnalysis a = analyse_intersections(*topology, s.x, pairs);
  EXPECT_TRUE(a.crossings.empty());
  EXPECT_TRUE(a.contours.empty());
  EXPECT_EQ(std::count(a.tangle.begin(), a.tangle.end(), 1), 0);
}

/// Analyses and pushes (no dynamics, velocities zero) up to `rounds` times; the rounds it took
/// to reach 0 intersecting pairs, or -1.
int untangle_statically(const Sheets& s, Positions x, const UntangleOptions& options, int rounds,
                        std::size_t* pushes = nullptr) {
  const auto topology = s.topology();
  Untangler untangler(topology, options);
  std::vector<Scalar> inv_mass(x.size(), 1);
  std::vector<Vec3> v(x.size(), Vec3::Zero());
  for (int r = 0; r < rounds; ++r) {
    untangler.analyse(x, inv_mass);
    if (!untangler.tangled()) return r;
    const UntangleStats stats = untangler.apply(inv_mass, x, v);
    if (pushes) *pushes += stats.pulls + stats.contour_moves;
  }
  return untangler.count(x) == 0 && untangler.pinch_pairs() == 0 ? rounds : -1;
}

/// The intersection contours of each of `sheets` as it is.
std::vector<Contour> contours_of(std::initializer_list<Sheets> sheets) {
  std::vector<Contour> out;
  for (const Sheets& s : sheets) {
    const auto t = s.topology();
    const IntersectionAnalysis a = analyse_intersections(*t, s.x, testing::intersecting_triangles(t, s.x));
    out.insert(out.end(), a.contours.begin(), a.contours.end());
  }
  return out;
}

TEST(Untangle, PullsTheBumpBackThrough) {
  const Sheets s = bump();
  UntangleOptions options;
  options.thickness = 0.01;
  options.max_step = 0.05;
  std::size_t pushes = 0;
  const int rounds = untangle_statically(s, s.x, options, 50, &pushes);
  EXPECT_GE(rounds, 1);
  EXPECT_LE(rounds, 50);
  EXPECT_GT(pushes, 0u);
}

TEST(Untangle, PullsTheFlapBackThrough) {
  const Sheets s = flap();
  UntangleOptions options;
  options.thickness = 0.01;
  options.max_step = 0.02;
  const int rounds = untangle_statically(s, s.x, options, 100);
  EXPECT_GE(rounds, 1);
  EXPECT_LE(rounds, 100);
}

/// Sheet B (ids 0..120) at y = 0 over the unit square, as in `flap`; A (16 × 2 quads, ids from
/// 121) a long fold over it along x: its crease (row j = 1, z = 0.52) at y = -0.02 for
/// x in [0.3, 0.7] (9 vertices, just beyond B) and at y = 0.02 elsewhere, its two layers rising
/// to y = 0.2 at z = 0.42 and 0.62. One closed curve, long (both layers cross B along the
/// stretch), which cuts off only the crease stretch below B: a band.
Sheets fold() {
  Sheets s;
  s.add(10, 10, [](Index i, Index j) { return Vec3(i * 0.1 - 0.013, 0, j * 0.1 - 0.017); });
  s.add(16, 2, [](Index i, Index j) {
    const Scalar x = 0.1 + i * 0.05;
    if (j != 1) return Vec3(x, 0.2, j == 0 ? 0.42 : 0.62);
    return Vec3(x, i >= 4 && i <= 12 ? -0.02 : 0.02, 0.52);
  });
  return s;
}

TEST(Untangle, LongFoldIsABandPulledBackWithTheSheetHeld) {
  const Sheets s = fold();
  const auto topology = s.topology();
  const auto pairs = testing::intersecting_triangles(topology, s.x);
  const IntersectionAnalysis a = analyse_intersections(*topology, s.x, pairs);
  ASSERT_EQ(a.contours.size(), 1u);
  const Contour& k = a.contours[0];
  EXPECT_FALSE(k.open);
  std::vector<Index> below;  // the crease's stretch below B
  for (Index v = 121; v < static_cast<Index>(s.x.size()); ++v) {
    if (s.x[static_cast<std::size_t>(v)].y() < 0) below.push_back(v);
  }
  ASSERT_EQ(below.size(), 9u);
  EXPECT_EQ(k.inside, below);
  EXPECT_GE(k.crossings.size(), 4 * below.size());
  EXPECT_TRUE(k.band);
  // The other handcrafted curves are no bands: what they cut off is not thin.
  for (const Contour& c : contours_of({bump(), flap()})) EXPECT_FALSE(c.band);

  // The pushes alone: the crease goes back over B, and B (the sheet the fold went through) is
  // held where it was.
  UntangleOptions options;
  options.thickness = 0.01;
  options.max_step = 0.02;
  Untangler untangler(topology, options);
  Positions x = s.x;
  std::vector<Scalar> inv_mass(x.size(), 1);
  std::vector<Vec3> v(x.size(), Vec3::Zero());
  int rounds = 0;
  for (; rounds < 20; ++rounds) {
    untangler.analyse(x, inv_mass);
    if (!untangler.tangled()) break;
    untangler.apply(inv_mass, x, v);
  }
  EXPECT_LT(rounds, 20) << "still tangled";
  EXPECT_EQ(testing::intersecting_triangles(topology, x).size(), 0u);
  for (Index i = 0; i <= 120; ++i) {
    EXPECT_EQ(x[static_cast<std::size_t>(i)], s.x[static_cast<std::size_t>(i)]) << "B's vertex " << i << " moved";
  }
  for (Index i : below) EXPECT_GT(x[static_cast<std::size_t>(i)].y(), 0) << i;
}

TEST(Untangle, ContourMinimisationOpensTheSlit) {
  const Sheets s = slit();
  UntangleOptions options;
  options.thickness = 0.01;
  options.max_step = 0.02;
  options.contour_step = 0.01;
  const int rounds = untangle_statically(s, s.x, options, 200);
  EXPECT_GE(rounds, 1);
  EXPECT_LE(rounds, 200);
  options.contour_step = 0;  // without it nothing moves
  EXPECT_EQ(untangle_statically(s, s.x, options, 20), -1);
}

/// A 2 × 2 lattice whose centre vertex 4's star passes through itself: the side (5, 8) of face
/// {4, 5, 8} pierces face {0, 1, 4}, which shares only vertex 4 with it (a pinch; no two faces
/// sharing no vertex intersect, so the `tt` count sees nothing).
Sheets pinched_star() {
  Sheets s;
  s.add(2, 2, [](Index i, Index j) { return Vec3(i, 0, j); });
  s.x[5] = Vec3(1.2, 0.5, 1);
  s.x[8] = Vec3(0.4, -0.5, 0);
  return s;
}

TEST(Untangle, FindsAPinchTheTtCountMisses) {
  const Sheets s = pinched_star();
  const auto topology = s.topology();
  const auto pairs = testing::intersecting_triangles(topology, s.x);
  EXPECT_EQ(pairs.size(), 0u);
  const testing::ExactIntersections exact = testing::exact_intersections(*topology, s.x);
  EXPECT_EQ(exact.disjoint, 0u);
  EXPECT_GE(exact.pinches, 1u);
  EXPECT_EQ(count_pinch_pairs(*topology, s.x), exact.pinches);
  for (const PinchCrossing& c : find_pinch_crossings(*topology, s.x)) EXPECT_EQ(c.vertex, 4);

  const IntersectionAnalysis a = analyse_intersections(*topology, s.x, pairs);
  EXPECT_EQ(a.pairs, 0u);
  EXPECT_EQ(a.pinch_pairs, exact.pinches);
  ASSERT_FALSE(a.contours.empty());
  EXPECT_EQ(a.contours[0].pinches, std::vector<Index>{4});
  // The corners of both faces of the pair are the tangle, so the fail-safe lets them through.
  for (Index v : {0, 1, 4, 5, 8}) EXPECT_EQ(a.tangle[static_cast<std::size_t>(v)], 1) << v;

  Sheets flat = s;  // the lattice back in its plane
  flat.x[5] = Vec3(2, 0, 1);
  flat.x[8] = Vec3(2, 0, 2);
  EXPECT_EQ(count_pinch_pairs(*flat.topology(), flat.x), 0u);
  EXPECT_EQ(testing::exact_intersections(*flat.topology(), flat.x).pinches, 0u);
}

// A pinch alone (no `tt` pair on its curve) is pulled apart: the end of the piercing side
// nearer the pierced face's plane goes back through it.
TEST(Untangle, PullsALonePinchApart) {
  const Sheets s = pinched_star();
  UntangleOptions options;
  options.thickness = 0.01;
  options.max_step = 0.05;
  const int rounds = untangle_statically(s, s.x, options, 100);
  EXPECT_GE(rounds, 1);
  EXPECT_LE(rounds, 100);
}

/// A strip (8 × 4 quads, rows j = 0..4) folded along its middle row j = 2 (the crease, at
/// y = 0), its sides rising to y = 0.2 at z = ±0.06; at column 4 the rows j = 1 and j = 3 have
/// swapped sides (z = ∓0.045), a stretch of the fold folded beyond flat: one closed curve
/// between the pinches 21 and 23 (the crease's vertices next to column 4), enclosing the
/// column's vertices 13, 22 and 31.
Sheets short_fold() {
  Sheets s;
  s.add(8, 4, [](Index i, Index j) {
    const Scalar side = static_cast<Scalar>(j - 2);
    const Scalar z = (i == 4 && (j == 1 || j == 3)) ? -1.5 * 0.03 * side : 0.03 * side;
    return Vec3(i * 0.1, std::abs(side) * 0.1, z + 0.001 * i * i);
  });
  return s;
}

TEST(Untangle, ShortFoldBeyondFlatIsShortenedAsWellAsPulled) {
  const Sheets s = short_fold();
  const auto topology = s.topology();
  const auto pairs = testing::intersecting_triangles(topology, s.x);
  const IntersectionAnalysis a = analyse_intersections(*topology, s.x, pairs);
  ASSERT_EQ(a.contours.size(), 1u);
  const Contour& k = a.contours[0];
  EXPECT_FALSE(k.open);
  EXPECT_EQ(k.pinches, (std::vector<Index>{21, 23}));
  EXPECT_EQ(k.inside, (std::vector<Index>{13, 22, 31}));
  EXPECT_TRUE(k.short_fold);
  EXPECT_FALSE(k.band);
  // The other handcrafted curves are no short folds (no pinch, or too much inside).
  for (const Contour& c : contours_of({bump(), flap(), fold(), pinched_star()})) EXPECT_FALSE(c.short_fold);

  // The pushes: pulls of the enclosed ends and, on every crossing, contour minimisation.
  UntangleOptions options;
  options.thickness = 0.005;
  options.max_step = 0.005;
  options.contour_step = 0.002;
  Untangler untangler(topology, options);
  Positions x = s.x;
  std::vector<Scalar> inv_mass(x.size(), 1);
  std::vector<Vec3> v(x.size(), Vec3::Zero());
  untangler.analyse(x, inv_mass);
  const UntangleStats first = untangler.apply(inv_mass, x, v);
  EXPECT_GT(first.pulls, 0u);
  EXPECT_EQ(first.contour_moves, a.crossings.size());
  EXPECT_GE(untangle_statically(s, s.x, options, 50), 1);
}

TEST(Untangle, TangleExemptsOnlyPairsWithBothSidesInIt) {
  std::vector<char> tangle{1, 0, 1, 0, 0};
  const Face f{1, 3, 4};
  EXPECT_TRUE(touches_tangle_on_both_sides(vertex_face_stencil(0, Face{2, 3, 4}, Vec3(1, 0, 0), Vec3::UnitZ()), tangle));
  EXPECT_FALSE(touches_tangle_on_both_sides(vertex_face_stencil(0, f, Vec3(1, 0, 0), Vec3::UnitZ()), tangle));
  EXPECT_FALSE(touches_tangle_on_both_sides(vertex_face_stencil(1, Face{0, 2, 3}, Vec3(1, 0, 0), Vec3::UnitZ()), tangle));
  EXPECT_TRUE(touches_tangle_on_both_sides(edge_edge_stencil(Edge{0, 1}, Edge{2, 3}, 0.5, 0.5, Vec3::UnitZ()), tangle));
  EXPECT_FALSE(touches_tangle_on_both_sides(edge_edge_stencil(Edge{0, 2}, Edge{3, 4}, 0.5, 0.5, Vec3::UnitZ()), tangle));
  EXPECT_FALSE(touches_tangle_on_both_sides(edge_edge_stencil(Edge{0, 1}, Edge{2, 3}, 0.5, 0.5, Vec3::UnitZ()), {}));
}

TEST(Untangle, RejectsBadOptions) {
  const auto topology = bump().topology();
  UntangleOptions options;
  EXPECT_THROW(Untangler(topology, options), InputError) << "a zero step";
  options.max_step = 0.1;
  options.contour_step = -1;
  EXPECT_THROW(Untangler(topology, options), InputError);
  options.contour_step = 0;
  options.border_step = std::numeric_limits<Scalar>::infinity();
  EXPECT_THROW(Untangler(topology, options), InputError);
}

}  // namespace
}  // namespace crumple::response
