// Mesh-level continuous collision detection (detect/continuous.hpp) against brute force: every
// vertex against every face it is not a corner of, every pair of edges sharing no vertex,
// through the same narrow phase. Identical impacts (pairs, TOIs bit for bit, outcomes) for
// every broad phase and thread count, on seeded lattices with random motion and on small real
// frame pairs; a tunnelling vertex the start and end boxes miss; bad input.
#include <crumple/core/error.hpp>
#include <crumple/detect/broad_phase/hash_grid.hpp>
#include <crumple/detect/broad_phase/kdop_tree.hpp>
#include <crumple/detect/broad_phase/sweep_prune.hpp>
#include <crumple/detect/continuous.hpp>
#include <crumple/detect/continuous_detail.hpp>
#include <crumple/geometry/ccd_detail.hpp>
#include <crumple/io/mesh_io.hpp>
#include <crumple/mesh/shapes.hpp>
#include <support/meshes.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <map>
#include <memory>
#include <mutex>
#include <numbers>
#include <numeric>
#include <random>
#include <sstream>
#include <string>
#include <tuple>
#include <vector>

namespace crumple {
namespace {

/// One impact as the tests compare it: kind, the pair's vertex ids, the TOI's bits, outcome.
using Key = std::tuple<char, Index, Index, Index, Index>;
struct Hit {
  Scalar toi;
  geometry::CcdOutcome outcome;
  bool operator==(const Hit&) const = default;
};
using Hits = std::map<Key, Hit>;

Hits hits_of(const ImpactSet& s) {
  Hits out;
  for (const auto& i : s.vf) out[{'v', i.vertex, i.face, -1, -1}] = {i.toi, i.outcome};
  for (const auto& i : s.ee) out[{'e', i.a[0], i.a[1], i.b[0], i.b[1]}] = {i.toi, i.outcome};
  return out;
}

/// All non-adjacent VF and EE pairs through the narrow phase, in the argument order the query
/// uses (vertex then the face's corners; the edge with the smaller vertex pair first).
Hits brute_force(const Topology& topo, PositionsView x0, PositionsView x1, Scalar delta) {
  geometry::CcdOptions options;
  options.min_separation = delta;
  Hits out;
  const auto s = [&](Index i) { return x0[static_cast<std::size_t>(i)]; };
  const auto e = [&](Index i) { return x1[static_cast<std::size_t>(i)]; };
  for (Index v = 0; v < topo.num_vertices(); ++v) {
    for (Index f = 0; f < topo.num_faces(); ++f) {
      const Face& t = topo.face(f);
      if (t[0] == v || t[1] == v || t[2] == v) continue;
      const auto r = geometry::vertex_face_ccd({s(v), s(t[0]), s(t[1]), s(t[2])}, {e(v), e(t[0]), e(t[1]), e(t[2])},
                                               options);
      if (r.hit) out[{'v', v, f, -1, -1}] = {r.toi, r.outcome};
    }
  }
  for (Index i = 0; i < topo.num_edges(); ++i) {
    for (Index j = i + 1; j < topo.num_edges(); ++j) {
      Edge a = topo.edge(i), b = topo.edge(j);
      if (a[0] == b[0] || a[0] == b[1] || a[1] == b[0] || a[1] == b[1]) continue;
      if (b < a) std::swap(a, b);
      const auto r =
          geometry::edge_edge_ccd({s(a[0]), s(a[1]), s(b[0]), s(b[1])}, {e(a[0]), e(a[1]), e(b[0]), e(b[1])}, options);
      if (r.hit) out[{'e', a[0], a[1], b[0], b[1]}] = {r.toi, r.outcome};
    }
  }
  return out;
}

Scalar earliest(const Hits& hits) {
  Scalar t = 1;
  for (const auto& [key, hit] : hits) t = std::min(t, hit.toi);
  return t;
}

std::string describe(const Hits& a, const Hits& b) {
  std::ostringstream out;
  int shown = 0;
  for (const auto& [key, hit] : a) {
    const auto it = b.find(key);
    if ((it == b.end() || !(it->second == hit)) && shown++ < 5) {
      out << "only/different in first: " << std::get<0>(key) << ' ' << std::get<1>(key) << ' ' << std::get<2>(key)
          << ' ' << std::get<3>(key) << ' ' << std::get<4>(key) << " toi " << hit.toi << '\n';
    }
  }
  for (const auto& [key, hit] : b) {
    if (!a.count(key) && shown++ < 10) {
      out << "only in second: " << std::get<0>(key) << ' ' << std::get<1>(key) << ' ' << std::get<2>(key) << ' '
          << std::get<3>(key) << ' ' << std::get<4>(key) << " toi " << hit.toi << '\n';
    }
  }
  return out.str();
}

/// Every broad phase, and variations of their parameters (kdop without `sweep`: a continuous
/// query sweeps anyway; tiny hash cells and table; another sweep axis).
const std::vector<std::string> kAllSpecs{"kdop", "kdop:sweep=off,leaf=4,arity=2", "hash", "hash:cell=0.5,table=97",
                                         "sap",  "sap:axis=z"};
const std::vector<std::string> kMethods{"kdop", "hash", "sap"};

/// Checks every broad phase and thread count against brute force; returns the impact count.
std::size_t check_all(const std::string& name, const std::shared_ptr<const Topology>& topo, PositionsView x0,
                      PositionsView x1, Scalar delta, const std::vector<std::string>& specs = kMethods) {
  const Hits expected = brute_force(*topo, x0, x1, delta);
  for (const std::string& spec : specs) {
    for (const int threads : {1, 3}) {
      ContinuousOptions options;
      options.min_separation = delta;
      options.method = MethodSpec::parse(spec);
      options.threads = threads;
      ContinuousQuery query(topo, options);
      ImpactSet impacts;
      query.query(x0, x1, impacts);
      const Hits got = hits_of(impacts);
      EXPECT_EQ(got.size(), impacts.size()) << "duplicate impacts";
      EXPECT_TRUE(got == expected) << name << " delta " << delta << " " << spec << " threads " << threads << ": "
                                   << got.size() << " impacts, brute force " << expected.size() << "\n"
                                   << describe(got, expected);
      EXPECT_EQ(collision_free_step(impacts), earliest(expected)) << name << " " << spec;
      // Sorted, and the impact's geometry is consistent.
      EXPECT_TRUE(std::is_sorted(impacts.vf.begin(), impacts.vf.end(), [](const auto& p, const auto& q) {
        return std::tie(p.vertex, p.face) < std::tie(q.vertex, q.face);
      }));
      EXPECT_TRUE(std::is_sorted(impacts.ee.begin(), impacts.ee.end(),
                                 [](const auto& p, const auto& q) { return std::tie(p.a, p.b) < std::tie(q.a, q.b); }));
      // Finite at every scale (squares of coordinates past 1e154 overflowed into NaN).
      for (const auto& i : impacts.vf) {
        EXPECT_TRUE(i.barycentric.allFinite() && i.normal.allFinite() && std::isfinite(i.distance)) << name;
        EXPECT_NEAR(i.barycentric.sum(), 1.0, 1e-12);
        EXPECT_TRUE(i.normal.norm() == 0 || std::abs(i.normal.norm() - 1) < 1e-12);
      }
      for (const auto& i : impacts.ee) {
        EXPECT_TRUE(std::isfinite(i.s) && std::isfinite(i.t) && i.normal.allFinite() && std::isfinite(i.distance))
            << name;
        EXPECT_TRUE(i.s >= 0 && i.s <= 1 && i.t >= 0 && i.t <= 1);
        EXPECT_EQ(topo->edge(i.edge0), i.a);
        EXPECT_EQ(topo->edge(i.edge1), i.b);
      }
      // Orphans and candidates together test each sub-pair once: the tests plus the box
      // rejections never exceed the brute-force pair count.
      const DetectorStats& st = query.stats();
      EXPECT_EQ(st.get("vf_impacts") + st.get("ee_impacts"), static_cast<double>(impacts.size()));
      // The slab test runs before every narrow-phase call and drops the sub-pairs the narrow
      // phase's hull filter would, but for a band of a few ulps of the scene's magnitude (its
      // bound is the scene's, the narrow phase's the query's): few remain for the narrow phase.
      const double slab_rejected = st.get("vf_box_rejected") + st.get("ee_box_rejected");
      EXPECT_LE(st.get("narrow_separated-hull"), 0.1 * slab_rejected) << name << " " << spec;
      // The step alone (the narrow phase searching only before the running minimum) is the
      // same number, bit for bit.
      EXPECT_EQ(query.collision_free_step(x0, x1), earliest(expected)) << name << " " << spec << " step only";
    }
  }
  return expected.size();
}

TEST(Continuous, LatticesWithRandomMotionMatchBruteForce) {
  std::size_t total = 0;
  for (const std::uint64_t seed : {1u, 2u, 3u}) {
    const TriMesh mesh = shapes::lattice(7, 6);
    const auto topo = mesh.topology_ptr();
    const Positions x0 = testing::crumple_lattice(mesh, 0.15, seed);
    // Large random motion: vertices cross faces and edges cross edges during the step.
    const Positions x1 = testing::jitter(testing::crumple_lattice(mesh, 0.25, seed + 10), 0.12, seed + 20);
    for (const Scalar delta : {0.0, 0.02}) {
      total += check_all("lattice seed " + std::to_string(seed), topo, x0, x1, delta, kAllSpecs);
    }
  }
  EXPECT_GT(total, 50u) << "the motion must make impacts, or the comparison proves little";
}

// Two triangles in the planes x = c and x = c + 2^-50, sliding along y: closer than the
// rounding band all step long, so hits at any δ > 0 (at δ = 0 the exact coplanarity signs
// prove them apart). c and c + 2^-50 lie on either side of the midpoint
// between the floats 1 and 1 + 2^-23: rounded to nearest, the face records' float boxes would
// put the triangles a float ulp apart (and drop the pair); rounded outwards they overlap.
TEST(Continuous, FaceBoxesAcrossAFloatBoundaryAreKept) {
  const Scalar c = 1 + 0x1p-24 - 0x1p-51, d = c + 0x1p-50;
  const Positions x0{{c, 0, 0}, {c, 1, 0}, {c, 0, 1}, {d, 0.2, 0.2}, {d, 1.2, 0.2}, {d, 0.2, 1.2}};
  Positions x1 = x0;
  for (std::size_t i = 3; i < 6; ++i) x1[i].y() -= 0.1;
  const TriMesh mesh = TriMesh::create(x0, {{0, 1, 2}, {3, 4, 5}});
  EXPECT_GT(check_all("float boundary", mesh.topology_ptr(), x0, x1, 1e-20, kAllSpecs), 0u);
}

// The face records keep float boxes rounded outwards: beyond float's range (overflow to the
// largest float or infinity, underflow to 0 or the smallest subnormal) the face test must stay
// weaker than the narrow phase's hull filter. A lattice scaled to 1e39 (beyond float's 3.4e38),
// to 1e-40 (float subnormals) and to 1e-200 (below them), also moved off the origin by 1e5 of its
// size, gives brute force's impacts. At 1e200 and 1e300 the narrow phase's squared lengths
// overflowed (inf <= inf made every bisection corner a witness: a spurious hit at t = 0 that
// kdop's k-DOPs, rightly apart, did not pass on, so kdop differed from brute force), and the
// impacts' barycentric coordinates were NaN; every impact field must be finite.
TEST(Continuous, ScaledLatticesBeyondFloatRangeMatchBruteForce) {
  const TriMesh mesh = shapes::lattice(7, 6);
  const auto topo = mesh.topology_ptr();
  const Positions y0 = testing::crumple_lattice(mesh, 0.15, 4);
  const Positions y1 = testing::jitter(testing::crumple_lattice(mesh, 0.25, 14), 0.12, 24);
  std::size_t total = 0;
  for (const Scalar scale : {1e39, 1e-40, 1e-200, 1e200, 1e300}) {
    // At 1e300 an offset of 1e5 would pass the narrow phase's range (2^1000 ~ 1.07e301).
    for (const Scalar offset : {0.0, scale > 1e250 ? 1.0 : 1e5}) {
      Positions x0 = y0, x1 = y1;
      for (Vec3& p : x0) p = scale * (p + Vec3::Constant(offset));
      for (Vec3& p : x1) p = scale * (p + Vec3::Constant(offset));
      total += check_all("lattice scaled " + std::to_string(scale), topo, x0, x1, 0.0);
      total += check_all("lattice scaled " + std::to_string(scale), topo, x0, x1, 0.02 * scale);
    }
  }
  EXPECT_GT(total, 50u);
}

// Scaling a step's positions and δ by 2^k (exact while they stay normal) changes no impact: the
// same pairs, TOIs and outcomes, from brute force (the narrow phase computes a query outside
// [2^-300, 2^300] scaled into [1, 2)) and from every broad phase (the query computes a step
// beyond [2^-64, 2^64) scaled, also past the narrow phase's range), distances times 2^k.
// Before, at 2^-1000 the narrow phase's underflow slack (2^-1000) was a third of the lattice's
// extent: every pair near contact was a conservative hit; at 2^600 the advancement was off.
TEST(Continuous, PowerOfTwoScalesGiveTheImpactsOfUnitScale) {
  const TriMesh mesh = shapes::lattice(7, 6);
  const auto topo = mesh.topology_ptr();
  Positions y0 = testing::crumple_lattice(mesh, 0.15, 4);
  Positions y1 = testing::jitter(testing::crumple_lattice(mesh, 0.25, 14), 0.12, 24);
  for (Positions* y : {&y0, &y1}) {
    for (Vec3& p : *y) p += Vec3::Constant(1.5);  // coordinates in [1, 3]: normal at 2^-1020
  }
  const auto scaled = [](PositionsView x, int k) {
    Positions out(x.begin(), x.end());
    for (Vec3& p : out) {
      for (int a = 0; a < 3; ++a) p[a] = std::scalbn(p[a], k);
    }
    return out;
  };
  for (const Scalar delta : {0.0, 0.02}) {
    const Hits unit = brute_force(*topo, y0, y1, delta);
    ASSERT_GT(unit.size(), 10u);
    ContinuousOptions options;
    options.min_separation = delta;
    const ImpactSet unit_impacts = continuous_impacts(topo, y0, y1, options);
    for (const int k : {-1020, -1000, -600, -80, 80, 600, 997, 1020}) {
      SCOPED_TRACE("2^" + std::to_string(k) + " delta " + std::to_string(delta));
      if (delta > 0 && k < -1000) continue;  // 0.02 2^k subnormal: another δ
      const Positions x0 = scaled(y0, k), x1 = scaled(y1, k);
      if (k < 998) {  // beyond, past the narrow phase's range (2^1000), a query is a conservative hit
        const Hits got = brute_force(*topo, x0, x1, std::scalbn(delta, k));
        EXPECT_TRUE(got == unit) << got.size() << " impacts, at unit scale " << unit.size() << "\n"
                                 << describe(got, unit);
        check_all("lattice at 2^" + std::to_string(k), topo, x0, x1, std::scalbn(delta, k));
      }
      options.min_separation = std::scalbn(delta, k);
      const ImpactSet impacts = continuous_impacts(topo, x0, x1, options);
      ASSERT_EQ(impacts.vf.size(), unit_impacts.vf.size());
      for (std::size_t i = 0; i < impacts.vf.size(); ++i) {
        EXPECT_EQ(impacts.vf[i].distance, std::scalbn(unit_impacts.vf[i].distance, k));
        EXPECT_EQ(impacts.vf[i].barycentric, unit_impacts.vf[i].barycentric);
      }
      ASSERT_EQ(impacts.ee.size(), unit_impacts.ee.size());
      for (std::size_t i = 0; i < impacts.ee.size(); ++i) {
        EXPECT_EQ(impacts.ee[i].distance, std::scalbn(unit_impacts.ee[i].distance, k));
        EXPECT_EQ(impacts.ee[i].s, unit_impacts.ee[i].s);
      }
      if (HasFailure()) return;
    }
  }
}

// Around a vertex of more than 64 faces (a star) the orphan sub-pairs are found each step from
// the faces' swept boxes, not listed (exact/stars.hpp): a two-turn fan whose turns pass through
// each other during the step, its centre the last vertex, plus a vertex of no face crossing
// it: every method and thread count gives brute force's impacts.
TEST(Continuous, StarsAndLoneVerticesMatchBruteForce) {
  const Index n = 160;
  Positions x0, x1;
  for (Index k = 0; k <= n; ++k) {
    const Scalar a = 4 * std::numbers::pi * static_cast<Scalar>(k) / static_cast<Scalar>(n);
    const Scalar turn = k * 2 < n ? 0 : 1;
    x0.emplace_back(std::cos(a), std::sin(a), 0.05 * turn);
    x1.emplace_back(std::cos(a), std::sin(a), -0.05 * turn);
  }
  x0.emplace_back(0, 0, 0);
  x1.emplace_back(0, 0, 0);
  x0.emplace_back(0.5, 0.1, 0.3);  // used by no face: drops through the fan
  x1.emplace_back(0.5, 0.1, -0.3);
  std::vector<Face> faces;
  for (Index k = 0; k < n; ++k) faces.push_back({k, k + 1, n + 1});
  const TriMesh mesh = TriMesh::create(x0, faces);
  const auto topo = mesh.topology_ptr();
  std::size_t total = 0;
  for (const Scalar delta : {0.0, 0.01}) total += check_all("two-turn fan", topo, x0, x1, delta, kAllSpecs);
  EXPECT_GT(total, 100u) << "the turns must cross";
  ContinuousQuery query(topo, {});
  ImpactSet impacts;
  query.query(x0, x1, impacts);
  EXPECT_EQ(query.stats().get("orphan_stars"), 1);
  EXPECT_GT(query.stats().get("orphan_star_pairs"), 0);
  EXPECT_EQ(query.stats().get("isolated_vertices"), 1);
}

TEST(Continuous, SmallMeshGroupMatchesBruteForce) {
  std::size_t total = 0;
  std::uint64_t seed = 7;
  for (const auto& [name, mesh] : testing::small_meshes()) {
    const auto topo = mesh.topology_ptr();
    const Positions x1 = testing::jitter(mesh.positions(), 0.15, ++seed);
    for (const Scalar delta : {0.0, 0.05}) total += check_all(name, topo, mesh.positions(), x1, delta);
  }
  EXPECT_GT(total, 10u);
}

TEST(Continuous, RealSmallMeshesMatchBruteForce) {
  std::size_t total = 0;
  {
    const TriMesh t0 = io::read_mesh(testing::data_path("ipc-toolkit-tests/thick-cloth/t0.ply"));
    const TriMesh t1 = io::read_mesh(testing::data_path("ipc-toolkit-tests/thick-cloth/t1.ply"));
    const Scalar diag = compute_bounds(t0.positions()).diagonal();
    for (const Scalar delta : {0.0, 1e-2 * diag}) {
      total += check_all("thick-cloth", t0.topology_ptr(), t0.positions(), t1.positions(), delta);
    }
  }
  for (const char* file : {"two-cubes-close.ply", "two-cubes-intersecting.ply"}) {
    const TriMesh m = io::read_mesh(testing::data_path(std::string("ipc-toolkit-tests/") + file));
    const Scalar diag = compute_bounds(m.positions()).diagonal();
    const Positions x1 = testing::jitter(m.positions(), 0.05 * diag, 42);
    for (const Scalar delta : {0.0, 1e-2 * diag}) {
      total += check_all(file, m.topology_ptr(), m.positions(), x1, delta);
    }
  }
  EXPECT_GT(total, 10u);
}

/// The faces of `mesh` whose centroids at `x0` are nearest to vertex `centre`, re-indexed into
/// a mesh of their own, with both frames' positions.
struct Region {
  std::shared_ptr<const Topology> topo;
  Positions x0, x1;
};
Region region(const TriMesh& mesh, PositionsView x1, Index centre, std::size_t faces) {
  const Topology& topo = mesh.topology();
  const PositionsView x0 = mesh.positions();
  const Vec3 c = x0[static_cast<std::size_t>(centre)];
  std::vector<std::pair<Scalar, Index>> order;
  for (Index f = 0; f < topo.num_faces(); ++f) {
    const Face& t = topo.face(f);
    Vec3 m = Vec3::Zero();
    for (const Index v : t) m += x0[static_cast<std::size_t>(v)];
    order.emplace_back((m / 3 - c).squaredNorm(), f);
  }
  std::sort(order.begin(), order.end());
  order.resize(std::min(faces, order.size()));
  std::vector<Index> remap(static_cast<std::size_t>(topo.num_vertices()), -1);
  Region r;
  std::vector<Face> kept;
  for (const auto& [d, f] : order) {
    Face nf;
    for (int k = 0; k < 3; ++k) {
      const auto v = static_cast<std::size_t>(topo.face(f)[static_cast<std::size_t>(k)]);
      if (remap[v] < 0) {
        remap[v] = static_cast<Index>(r.x0.size());
        r.x0.push_back(x0[v]);
        r.x1.push_back(x1[v]);
      }
      nf[static_cast<std::size_t>(k)] = remap[v];
    }
    kept.push_back(nf);
  }
  r.topo = TriMesh::create(r.x0, kept).topology_ptr();
  return r;
}

TEST(Continuous, RegionsOfRealFramePairsMatchBruteForce) {
  // Patches of two consecutive frames of the sample CCD scenes, around a vertex of one of the
  // full scene's impacts at δ = 0, where surfaces meet. Cloth-ball's cloth rests on itself
  // (thousands of impacts in a small patch, each costing the narrow phase hundreds of boxes at
  // δ > 0), so it is taken smaller and at δ = 0 only.
  struct Case {
    const char* f0;
    const char* f1;
    Index centre;
    std::size_t faces;
    bool with_delta;
  };
  const Case cases[] = {
      {"sample-scalable-ccd/cloth-funnel/frames/227.ply", "sample-scalable-ccd/cloth-funnel/frames/228.ply", 8481, 700,
       true},
      {"sample-scalable-ccd/cloth-ball/frames/cloth_ball92.ply", "sample-scalable-ccd/cloth-ball/frames/cloth_ball93.ply",
       100, 250, false},
  };
#ifdef CRUMPLE_SANITIZED
  const std::size_t shrink = 3;
#else
  const std::size_t shrink = 1;
#endif
  for (const Case& c : cases) {
    const TriMesh m0 = io::read_mesh(testing::data_path(c.f0));
    const TriMesh m1 = io::read_mesh(testing::data_path(c.f1));
    const Region r = region(m0, m1.positions(), c.centre, c.faces / shrink);
    const Scalar diag = compute_bounds(m0.positions()).diagonal();
    std::size_t total = check_all(c.f0, r.topo, r.x0, r.x1, 0);
    if (c.with_delta) total += check_all(c.f0, r.topo, r.x0, r.x1, 1e-3 * diag);
    EXPECT_GT(total, 0u) << c.f0;
  }
}

TEST(Continuous, ATunnellingVertexIsFoundByEveryBroadPhase) {
  // A triangle at rest in z = 0 and a far-away small triangle falling through it in one step:
  // its boxes at t = 0 and t = 1 are 20 apart, only the swept box meets the first triangle.
  const auto topo = TriMesh::create({Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0), Vec3(0.2, 0.2, 10),
                                     Vec3(0.3, 0.2, 10), Vec3(0.2, 0.3, 10)},
                                    {{0, 1, 2}, {3, 4, 5}})
                        .topology_ptr();
  Positions x0{Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0), Vec3(0.2, 0.2, 10), Vec3(0.3, 0.2, 10), Vec3(0.2, 0.3, 10)};
  Positions x1 = x0;
  for (int v = 3; v < 6; ++v) x1[static_cast<std::size_t>(v)].z() = -10;
  for (const std::string& spec : kAllSpecs) {
    ContinuousOptions options;
    options.method = MethodSpec::parse(spec);
    const ImpactSet impacts = continuous_impacts(topo, x0, x1, options);
    ASSERT_EQ(impacts.vf.size(), 3u) << spec;  // each falling vertex through the resting face
    EXPECT_EQ(impacts.vf[0].vertex, 3);
    EXPECT_EQ(impacts.vf[0].face, 0);
    const Scalar step = collision_free_step(impacts);
    EXPECT_LE(step, 0.5) << spec;
    EXPECT_GE(step, 0.5 - 2e-6) << spec;
    EXPECT_NEAR(impacts.vf[0].normal.z(), 1, 1e-6) << spec;  // from the face towards the vertex, above it
  }
}

TEST(Continuous, FacesApartOnDifferentAxesAtTheTwoEndsAreKept) {
  // A small triangle 0.3 beyond a resting one on x at t = 0 and 0.2 beyond it on y at t = 1,
  // passing through it at t = 1/2: apart at both ends, but not on one axis, so the pair must
  // stay a candidate (a slab test that took any axis at each end would lose every impact).
  const Vec3 c0(1.3, -0.7, 0.5), c1(-0.8, 1.2, -0.5);
  const Vec3 d1(0.05, 0, 0.01), d2(0, 0.05, 0.02);
  const auto topo =
      TriMesh::create({Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0), c0, c0 + d1, c0 + d2}, {{0, 1, 2}, {3, 4, 5}})
          .topology_ptr();
  const Positions x0{Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0), c0, c0 + d1, c0 + d2};
  const Positions x1{Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0), c1, c1 + d1, c1 + d2};
  for (const Scalar delta : {0.0, 0.01}) {
    EXPECT_GT(check_all("apart on x, then on y", topo, x0, x1, delta, kAllSpecs), 0u) << delta;
  }
}

TEST(Continuous, BroadPhasesStreamTheSameCandidatesInBoundedChunks) {
  // 3,200 faces with boxes grown by 0.06 (edges 0.025): about 10 × kStreamChunk candidates.
  const TriMesh mesh = shapes::lattice(40, 40);
  const Positions x0 = testing::crumple_lattice(mesh, 0.1, 5);
  const Positions x1 = testing::jitter(x0, 0.02, 6);
  std::vector<std::unique_ptr<BroadPhase>> phases;
  phases.push_back(std::make_unique<KdopTree>(KdopParams{}));
  phases.push_back(std::make_unique<HashGrid>(HashParams{}));
  phases.push_back(std::make_unique<SweepPrune>(SapParams{}));
  for (auto& phase : phases) {
    for (const int threads : {1, 3}) {
      phase->build(mesh.topology());
      FrameInput in{x0, x1, 0.06, threads, false, {}, true};
      DetectorStats stats;
      phase->update(in, stats);
      CandidateBuffer kept;
      phase->self_pairs(kept, stats);
      std::vector<FacePair> all;
      for (const auto& chunk : kept.chunks()) all.insert(all.end(), chunk.begin(), chunk.end());
      std::sort(all.begin(), all.end());
      ASSERT_GT(all.size(), 8 * CandidateBuffer::kStreamChunk) << to_string(phase->method());
      CandidateBuffer streamed;
      std::mutex mutex;
      std::vector<FacePair> got;
      std::size_t largest = 0;
      streamed.set_consumer([&](std::span<const FacePair> chunk) {
        const std::lock_guard lock(mutex);
        got.insert(got.end(), chunk.begin(), chunk.end());
        largest = std::max(largest, chunk.size());
      });
      phase->update(in, stats);
      phase->self_pairs(streamed, stats);
      EXPECT_TRUE(streamed.chunks().empty());
      EXPECT_EQ(streamed.total(), all.size());
      std::sort(got.begin(), got.end());
      EXPECT_TRUE(got == all) << to_string(phase->method()) << " threads " << threads;
      // A chunk is handed on once it holds kStreamChunk candidates, after the unit of work
      // (bucket, box, traversal task) that filled it: far below the total.
      EXPECT_LT(largest, 4 * CandidateBuffer::kStreamChunk) << to_string(phase->method()) << " threads " << threads;
    }
  }
}

TEST(Continuous, NoMotionAndFarApartGivesAFullStep) {
  const TriMesh mesh = shapes::lattice(4, 4);
  const ImpactSet impacts = continuous_impacts(mesh.topology_ptr(), mesh.positions(), mesh.positions());
  EXPECT_TRUE(impacts.empty());
  EXPECT_EQ(collision_free_step(impacts), 1.0);
  EXPECT_EQ(collision_free_step(mesh.topology_ptr(), mesh.positions(), mesh.positions()), 1.0);
}

TEST(Continuous, WithinDeltaAtTheStartGivesAZeroStep) {
  const TriMesh mesh = shapes::folded_cloth({.n = 8, .gap = 0.05, .wave = 0.0, .thickness = 0.06});
  ContinuousOptions options;
  options.min_separation = 0.1;  // more than the fold's gap: pairs are within δ at t = 0
  EXPECT_EQ(collision_free_step(mesh.topology_ptr(), mesh.positions(), mesh.positions(), options), 0.0);
}

TEST(Continuous, FunnelStepAtZeroSeparationIsPositive) {
  // cloth-funnel 227->228 at δ = 0: no pair touches at t = 0, but bisection alone ended some
  // queries at its box budget with a TOI of 0, so the collision-free step was 0. The
  // narrow phase's conservative advancement starts every such search later than 0.
  const TriMesh m0 = io::read_mesh(testing::data_path("sample-scalable-ccd/cloth-funnel/frames/227.ply"));
  const TriMesh m1 = io::read_mesh(testing::data_path("sample-scalable-ccd/cloth-funnel/frames/228.ply"));
  ContinuousQuery query(m0.topology_ptr(), {});
  ImpactSet impacts;
  query.query(m0.positions(), m1.positions(), impacts);
  ASSERT_FALSE(impacts.empty());
  const Scalar step = collision_free_step(impacts);
  EXPECT_GT(step, 0.01);
  EXPECT_LT(step, 1.0);
  EXPECT_EQ(query.collision_free_step(m0.positions(), m1.positions()), step);
  for (const auto& i : impacts.vf) EXPECT_GT(i.toi, 0) << "vf " << i.vertex << ' ' << i.face;
  for (const auto& i : impacts.ee) EXPECT_GT(i.toi, 0) << "ee " << i.edge0 << ' ' << i.edge1;
}

TEST(Continuous, FaceBoxKernelsGiveTheScalarSlabTest) {
  // Both kernels of the face-level test against the test one difference at a time, on boxes
  // whose twelve differences lo − hi are each drawn exactly at the bound (not apart: the test
  // is strict), one float step above or below it, far on either side, or with an infinite
  // bound (∞ − ∞ is NaN: not apart), in every combination of sides, axes and times.
  const auto reference = [](const detail::FaceBoxes& a, const detail::FaceBoxes& b, Scalar bound) {
    bool apart = false;
    for (std::size_t k = 0; k < 3; ++k) {
      const auto above = [&](const detail::FaceBoxes& f, const detail::FaceBoxes& g, std::size_t j) {
        return Scalar(f.lo[j]) - Scalar(g.hi[j]) > bound;
      };
      apart = apart || (above(a, b, k) && above(a, b, k + 3)) || (above(b, a, k) && above(b, a, k + 3));
    }
    return apart;
  };
  constexpr float kInf = std::numeric_limits<float>::infinity();
  std::mt19937 rng(42);
  std::uniform_int_distribution<int> grid(-256, 256), pick(0, 8);
  std::size_t apart = 0, draws = 0, mismatches = 0;
  for (const Scalar bound : {0.25, 0x1p-20}) {
    const auto bound_f = static_cast<float>(bound);
    // lo − hi for one difference, hi on the 1/64 grid (lo − hi then exact in float and double).
    const auto draw = [&](float& lo, float& hi) {
      hi = static_cast<float>(grid(rng)) / 64;
      switch (pick(rng)) {
        case 0: lo = hi + bound_f; break;                                // at the bound: not apart
        case 1: lo = std::nextafter(hi + bound_f, kInf); break;         // just above
        case 2: lo = std::nextafter(hi + bound_f, -kInf); break;        // just below
        case 3: lo = hi + 4; break;                                      // far above
        case 4: lo = hi - 4; break;                                      // far below (overlap)
        case 5: lo = kInf; hi = kInf; break;                             // NaN difference
        case 6: lo = kInf; break;                                        // +∞
        case 7: hi = -kInf; break;                                       // +∞
        default: lo = -kInf; break;                                      // −∞
      }
    };
    for (int n = 0; n < 20000; ++n) {
      detail::FaceBoxes a, b;
      for (std::size_t j = 0; j < 6; ++j) {
        draw(a.lo[j], b.hi[j]);
        draw(b.lo[j], a.hi[j]);
      }
      const bool expected = reference(a, b, bound);
      apart += expected ? 1 : 0;
      ++draws;
      for (const bool avx2 : {false, true}) {
        if (avx2 && !geometry::detail::ccd_has_avx2()) continue;
        if (detail::face_boxes_apart(a, b, bound, avx2) != expected) ++mismatches;
      }
    }
  }
  EXPECT_EQ(mismatches, 0u);
  EXPECT_GT(apart, draws / 10);
  EXPECT_LT(apart, draws - draws / 10);
}

TEST(Continuous, SortedRunsMergeToTheSortOfAll) {
  // The impacts' merge: runs of unique keys (each run sorted, the runs interleaved), some
  // empty, in any number, against std::sort of the whole; equal keys are not needed (the
  // impacts' keys are unique). Payloads ride along, so a key moved without its record fails.
  std::mt19937 rng(7);
  using Item = std::pair<int, int>;
  const auto key_less = [](const Item& x, const Item& y) { return x.first < y.first; };
  for (const int runs : {0, 1, 2, 3, 17, 300}) {
    for (int draw = 0; draw < 20; ++draw) {
      std::vector<int> keys(static_cast<std::size_t>(std::uniform_int_distribution<int>(0, 2000)(rng)));
      std::iota(keys.begin(), keys.end(), 0);
      std::shuffle(keys.begin(), keys.end(), rng);
      std::vector<Item> items;
      std::vector<std::size_t> ends;
      std::size_t begin = 0;
      for (int r = 0; r < runs; ++r) {
        const std::size_t end = r + 1 == runs ? keys.size()
                                              : std::uniform_int_distribution<std::size_t>(begin, keys.size())(rng);
        std::vector<Item> run;
        for (std::size_t i = begin; i < end; ++i) run.push_back({keys[i], -keys[i]});
        std::sort(run.begin(), run.end(), key_less);
        items.insert(items.end(), run.begin(), run.end());
        ends.push_back(end);
        begin = end;
      }
      std::vector<Item> expected = items;
      std::sort(expected.begin(), expected.end(), key_less);
      detail::merge_sorted_runs(items, ends, key_less);
      ASSERT_EQ(items, expected) << runs << " runs, draw " << draw;
    }
  }
}

TEST(Continuous, BadInputThrowsInputError) {
  const TriMesh mesh = shapes::lattice(3, 3);
  const auto topo = mesh.topology_ptr();
  const Positions& x = mesh.positions();
  ContinuousQuery query(topo, {});
  ImpactSet out;
  const Positions shorter(x.begin(), x.end() - 1);
  EXPECT_THROW(query.query(shorter, x, out), InputError);
  EXPECT_THROW(query.query(x, shorter, out), InputError);
  Positions nan = x;
  nan[5].y() = std::numeric_limits<Scalar>::quiet_NaN();
  try {
    query.query(x, nan, out);
    ADD_FAILURE() << "NaN accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("vertex 5"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("current"), std::string::npos) << e.what();
  }
  Positions inf = x;
  inf[2].x() = std::numeric_limits<Scalar>::infinity();
  EXPECT_THROW(query.query(inf, x, out), InputError);
  EXPECT_TRUE(out.empty());
  ContinuousOptions bad;
  bad.min_separation = -1;
  EXPECT_THROW(ContinuousQuery(topo, bad), InputError);
  bad.min_separation = std::numeric_limits<Scalar>::quiet_NaN();
  EXPECT_THROW(ContinuousQuery(topo, bad), InputError);
  ContinuousOptions naive;
  naive.method = MethodSpec(Method::Naive);
  EXPECT_THROW(ContinuousQuery(topo, naive), InputError);
  // The query still works after the errors.
  query.query(x, x, out);
  EXPECT_TRUE(out.empty());
}

TEST(Continuous, ImpactsTextIsStable) {
  ImpactSet set;
  VertexFaceImpact vf;
  vf.vertex = 3;
  vf.face = 0;
  vf.toi = 0.5;
  vf.barycentric = Vec3(0.25, 0.25, 0.5);
  vf.normal = Vec3(0, 0, 1);
  set.vf.push_back(vf);
  EdgeEdgeImpact ee;
  ee.a = {0, 1};
  ee.b = {2, 5};
  ee.toi = 0.1;
  ee.s = 1.0 / 3;
  ee.t = 1;
  ee.normal = Vec3(0, -1, 0);
  set.ee.push_back(ee);
  std::ostringstream out;
  write_impacts(out, set);
  EXPECT_EQ(out.str(),
            "vf 3 0 0.5 0.25 0.25 0.5 0 0 1\n"
            "ee 0 1 2 5 0.10000000000000001 0.33333333333333331 1 0 -1 0\n");
}

}  // namespace
}  // namespace crumple

