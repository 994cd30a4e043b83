// The continuous fail-safe alone (`CcdFailSafe`): a frame whose proposed motion passes
// triangles through each other ends intersection-free, by each stage and by the whole.
#include <crumple/core/error.hpp>
#include <crumple/detect/detector.hpp>
#include <crumple/geometry/ccd.hpp>
#include <crumple/mesh/shapes.hpp>
#include <crumple/response/fail_safe.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <random>

#include "support/intersections.hpp"

namespace crumple::response {
namespace {

/// VF/EE pairs that touch (δ = 0) during the linear motion from `x0` to `x1`.
std::size_t touching_pairs(std::shared_ptr<const Topology> topology, PositionsView x0, PositionsView x1) {
  ContinuousOptions options;
  options.threads = 1;
  return continuous_impacts(std::move(topology), x0, x1, options).size();
}

/// Triangle A lies in z = 0; triangle B stands upright above it and is moved 1.25 down in one
/// frame of 0.1 s, ending half through A.
struct Crossing {
  std::shared_ptr<const Topology> topology;
  Positions start{Vec3(0, 0, 0),     Vec3(1, 0, 0),     Vec3(0, 1, 0),
                  Vec3(0.2, 0.2, 1), Vec3(0.4, 0.2, 1), Vec3(0.3, 0.2, 1.5)};
  Positions end;
  Positions velocity;
  std::vector<Scalar> inv_mass{1, 1, 1, 1, 1, 1};
  Crossing() {
    topology = TriMesh::create(start, {Face{0, 1, 2}, Face{3, 4, 5}}).topology_ptr();
    end = start;
    for (int i = 3; i < 6; ++i) end[static_cast<std::size_t>(i)].z() -= 1.25;
    for (std::size_t i = 0; i < 6; ++i) velocity.push_back((end[i] - start[i]) / 0.1);
  }
};

FailSafeOptions options(int impulse_rounds, int zone_rounds) {
  FailSafeOptions o;
  o.min_separation = 1e-3;
  o.impulse_rounds = impulse_rounds;
  o.zone_rounds = zone_rounds;
  o.query.threads = 1;
  return o;
}

TEST(FailSafe, TwoTrianglesMovingThroughEachOtherEndApart) {
  for (const auto& [impulses, zones] : {std::pair{3, 8}, std::pair{0, 8}, std::pair{0, 0}}) {
    SCOPED_TRACE(::testing::Message() << impulses << " impulse rounds, " << zones << " zone rounds");
    Crossing c;
    ASSERT_EQ(testing::intersecting_triangles(c.topology, c.start).size(), 0u);
    ASSERT_GT(testing::intersecting_triangles(c.topology, c.end).size(), 0u) << "the proposed end intersects";
    CcdFailSafe safe(c.topology, options(impulses, zones));
    const FailSafeStats stats = safe.apply(c.start, c.inv_mass, 0.1, c.end, c.velocity);
    EXPECT_GT(stats.impacts, 0u);
    EXPECT_EQ(testing::intersecting_triangles(c.topology, c.end).size(), 0u);
    EXPECT_EQ(touching_pairs(c.topology, c.start, c.end), 0u) << "no pair touches during the corrected motion";
    // Velocities follow the corrected positions: the frame's mean velocity, or 0 when frozen.
    for (std::size_t i = 0; i < 6; ++i) {
      const Vec3 mean = (c.end[i] - c.start[i]) / 0.1;
      EXPECT_LT((c.velocity[i] - mean).norm(), 1e-9) << "vertex " << i;
    }
    if (impulses > 0) {
      // An inelastic impulse splits the approach: B stops, A moves down to meet it halfway
      // in momentum (B's vertex on A's face or A's edge on B's), no freezing needed.
      EXPECT_EQ(stats.frozen, 0u);
    }
    if (impulses == 0 && zones == 0) {
      EXPECT_GT(stats.frozen, 0u) << "only the fallback ran";
    }
  }
}

TEST(FailSafe, FallbackAloneKeepsFrozenVerticesAtTheirStart) {
  Crossing c;
  CcdFailSafe safe(c.topology, options(0, 0));
  const FailSafeStats stats = safe.apply(c.start, c.inv_mass, 0.1, c.end, c.velocity);
  ASSERT_GT(stats.frozen, 0u);
  std::size_t still = 0, b_still = 0;
  for (std::size_t i = 0; i < 6; ++i) {
    if (c.end[i] == c.start[i]) {
      ++still;
      if (i >= 3) ++b_still;
      EXPECT_EQ(c.velocity[i], Vec3::Zero()) << "vertex " << i;
    }
  }
  EXPECT_GE(still, stats.frozen) << "every frozen vertex is exactly at its start";
  EXPECT_GT(b_still, 0u) << "B, the moving triangle, was stopped";
}

// A lattice (8x8) thrown into a random tangle in one frame: every stage may run; the end is
// intersection-free and no pair touches on the way.
TEST(FailSafe, RandomTangleOfALatticeEndsIntersectionFree) {
#ifdef CRUMPLE_SANITIZED
  const int kSeeds = 1;
  const Index kSide = 5;  // a smaller lattice under the sanitizers, the same assertions
#else
  const int kSeeds = 2;
  const Index kSide = 8;
#endif
  for (const auto& [impulses, zones] : {std::pair{3, 8}, std::pair{0, 8}, std::pair{0, 0}}) {
    for (int seed = 1; seed <= kSeeds; ++seed) {
      SCOPED_TRACE(::testing::Message() << "seed " << seed << ", " << impulses << " impulse rounds, " << zones
                                      << " zone rounds");
      const TriMesh lattice = shapes::lattice(kSide, kSide);
      const auto topology = lattice.topology_ptr();
      const Positions start = lattice.positions();
      std::mt19937_64 rng(static_cast<std::uint64_t>(seed));
      std::uniform_real_distribution<Scalar> d(-0.3, 0.3);
      Positions end = start, velocity(start.size(), Vec3::Zero());
      for (Vec3& p : end) p += Vec3(d(rng), d(rng), d(rng));
      ASSERT_GT(testing::intersecting_triangles(topology, end).size(), 0u) << "the proposed end is tangled";
      std::vector<Scalar> inv_mass(start.size(), 1);
      inv_mass[0] = 0;  // a pinned corner
      CcdFailSafe safe(topology, options(impulses, zones));
      const FailSafeStats stats = safe.apply(start, inv_mass, 1.0 / 60, end, velocity);
      EXPECT_GT(stats.impacts, 0u);
      EXPECT_EQ(stats.static_left, 0u);
      EXPECT_EQ(testing::intersecting_triangles(topology, end).size(), 0u);
      EXPECT_EQ(touching_pairs(topology, start, end), 0u);
      if (impulses == 0 && zones > 0) {
        EXPECT_GT(stats.zone_vertices, 0u);
      }
      if (impulses == 0 && zones == 0) {
        EXPECT_GT(stats.frozen, 0u);
      }
    }
  }
}

// Issue 43 (crumple:n=100 heating up): impact zones move vertices by about their whole
// proposed displacement and leave the springs at a zone's border stretched. On random tangles
// of a lattice where 3 impulse rounds left impacts to the zones, the default rounds settle
// every impact by impulses alone: no zone, nothing frozen, and the end is intersection-free.
TEST(FailSafe, DefaultImpulseRoundsSettleTanglesWithoutZones) {
  struct Case {
    Scalar amplitude;
    int seed;
  };
  int zoned_with_three = 0;
  for (const Case c : {Case{0.2, 2}, Case{0.2, 3}, Case{0.3, 3}, Case{0.5, 1}}) {
    SCOPED_TRACE(::testing::Message() << "amplitude " << c.amplitude << ", seed " << c.seed);
    const TriMesh lattice = shapes::lattice(10, 10);
    const auto topology = lattice.topology_ptr();
    const Positions start = lattice.positions();
    std::mt19937_64 rng(static_cast<std::uint64_t>(c.seed));
    std::uniform_real_distribution<Scalar> d(-c.amplitude, c.amplitude);
    Positions proposed = start;
    for (Vec3& p : proposed) p += Vec3(d(rng), d(rng), d(rng));
    const std::vector<Scalar> inv_mass(start.size(), 1);
    FailSafeOptions defaults;
    defaults.min_separation = 1e-3;
    defaults.query.threads = 1;
    FailSafeOptions three = defaults;
    three.impulse_rounds = 3;
    for (const bool by_default : {false, true}) {
      CcdFailSafe safe(topology, by_default ? defaults : three);
      Positions end = proposed, velocity(start.size(), Vec3::Zero());
      const FailSafeStats stats = safe.apply(start, inv_mass, 1.0 / 60, end, velocity);
      ASSERT_GT(stats.impacts, 0u);
      EXPECT_EQ(testing::intersecting_triangles(topology, end).size(), 0u);
      if (by_default) {
        EXPECT_EQ(stats.zone_vertices, 0u);
        EXPECT_EQ(stats.frozen, 0u);
        EXPECT_LT(stats.impulse_rounds, defaults.impulse_rounds) << "the impulses converged";
      } else if (stats.zone_vertices > 0) {
        ++zoned_with_three;
      }
    }
  }
  EXPECT_EQ(zoned_with_three, 4) << "each case needs more than 3 impulse rounds";
}

// The later queries restricted to the vertices whose ends moved (`restrict_queries`) give
// the same impacts as full queries, so the whole correction is the same, bit for bit: every
// stage, on random tangles of a lattice (hundreds of impacts, several queries), and over a
// second call from the same start (continuing from the first call's last query).
TEST(FailSafe, RestrictedQueriesGiveTheSameCorrection) {
  const Index kSide = 8;  // small enough under the sanitizers too (~1 s)
  int most_queries = 0, later_with_impacts = 0;
  for (const auto& [impulses, zones] : {std::pair{3, 8}, std::pair{0, 8}, std::pair{0, 0}, std::pair{1, 1}}) {
    for (const Scalar amplitude : {0.15, 0.3}) {
      SCOPED_TRACE(::testing::Message() << impulses << " impulse rounds, " << zones << " zone rounds, amplitude "
                                      << amplitude);
      const TriMesh lattice = shapes::lattice(kSide, kSide);
      const auto topology = lattice.topology_ptr();
      const Positions start = lattice.positions();
      std::mt19937_64 rng(7);
      std::uniform_real_distribution<Scalar> d(-amplitude, amplitude);
      Positions proposed = start;
      for (Vec3& p : proposed) p += Vec3(d(rng), d(rng), d(rng));
      std::vector<Scalar> inv_mass(start.size(), 1);
      inv_mass[0] = 0;
      FailSafeStats stats[2], stats2[2], stats3[2];
      Positions end[2], velocity[2];
      for (const bool restrict : {false, true}) {
        FailSafeOptions o = options(impulses, zones);
        o.restrict_queries = restrict;
        o.restricted_share = 1;  // every later query restricted, however many ends moved
        o.query.threads = restrict ? 3 : 1;
        CcdFailSafe safe(topology, o);
        end[restrict] = proposed;
        velocity[restrict] = Positions(start.size(), Vec3::Zero());
        stats[restrict] = safe.apply(start, inv_mass, 1.0 / 60, end[restrict], velocity[restrict]);
        EXPECT_EQ(touching_pairs(topology, start, end[restrict]), 0u);
        // A second call from the same start after some ends moved (as the simulation's obstacle
        // rounds do) continues from the last query; a third from another start queries afresh.
        for (std::size_t i = 0; i < start.size(); i += 5) end[restrict][i] += Vec3(0.1, -0.2, 0.05);
        stats2[restrict] = safe.apply(start, inv_mass, 1.0 / 60, end[restrict], velocity[restrict]);
        std::mt19937_64 later(11);
        Positions next = start;  // another start (a height field: no intersection), the same ends mostly
        for (Vec3& p : next) p.z() = 0.25 * std::sin(7 * p.x()) * std::cos(5 * p.y());
        // Every seventh end moves: the others are the last query's.
        for (std::size_t i = 0; i < start.size(); i += 7) end[restrict][i] += Vec3(d(later), d(later), d(later));
        stats3[restrict] = safe.apply(next, inv_mass, 1.0 / 60, end[restrict], velocity[restrict]);
        EXPECT_EQ(touching_pairs(topology, next, end[restrict]), 0u);
      }
      for (const FailSafeStats* later : {stats2, stats3}) {
        later_with_impacts += later[0].impacts > 0 ? 1 : 0;
        EXPECT_EQ(later[1].queries + later[1].unchanged, later[0].queries);
        EXPECT_EQ(later[1].impacts, later[0].impacts);
        EXPECT_EQ(later[1].frozen, later[0].frozen);
      }
      EXPECT_GE(stats[1].queries, 2) << "the correction must need later queries";
      most_queries = std::max(most_queries, stats[1].queries + stats[1].unchanged);
      EXPECT_EQ(stats[1].queries + stats[1].unchanged, stats[0].queries);
      EXPECT_EQ(stats[1].impacts, stats[0].impacts);
      EXPECT_EQ(stats[1].zone_vertices, stats[0].zone_vertices);
      EXPECT_EQ(stats[1].frozen, stats[0].frozen);
      EXPECT_EQ(stats[1].static_left, stats[0].static_left);
      EXPECT_TRUE(end[1] == end[0]) << "the corrected ends differ (after the third call)";
      EXPECT_TRUE(velocity[1] == velocity[0]) << "the corrected velocities differ";
    }
  }
  EXPECT_GT(most_queries, 3) << "some correction must take several restricted queries";
  EXPECT_GE(later_with_impacts, 12) << "most later calls (of 16) must have impacts to correct";
}

// Rounds that cannot change the motion are skipped, not queried: with every vertex pinned no
// impulse applies and a zone cannot move, so after one impulse round and one zone round (whose
// zones then stop growing) the fallback freezes the pair. Before, every impulse and zone round
// ran (and counted) a query: 30 of them.
TEST(FailSafe, RoundsThatCannotChangeTheMotionAreSkipped) {
  Crossing c;
  std::fill(c.inv_mass.begin(), c.inv_mass.end(), 0);
  CcdFailSafe safe(c.topology, options(20, 8));
  const FailSafeStats stats = safe.apply(c.start, c.inv_mass, 0.1, c.end, c.velocity);
  EXPECT_GT(stats.impacts, 0u);
  EXPECT_EQ(stats.impulse_rounds, 1);
  EXPECT_EQ(stats.zone_rounds, 2);
  EXPECT_LE(stats.queries, 5);
  EXPECT_GT(stats.frozen, 0u);
  EXPECT_EQ(testing::intersecting_triangles(c.topology, c.end).size(), 0u);
  EXPECT_EQ(touching_pairs(c.topology, c.start, c.end), 0u);
}

TEST(FailSafe, CleanFrameIsLeftBitForBit) {
  Crossing c;
  for (int i = 3; i < 6; ++i) c.end[static_cast<std::size_t>(i)].z() = c.start[static_cast<std::size_t>(i)].z() - 0.5;
  const Positions before = c.end, v_before = c.velocity;
  CcdFailSafe safe(c.topology, options(3, 8));
  const FailSafeStats stats = safe.apply(c.start, c.inv_mass, 0.1, c.end, c.velocity);
  EXPECT_EQ(stats.queries, 1);
  EXPECT_EQ(stats.impacts, 0u);
  EXPECT_EQ(c.end, before);
  EXPECT_EQ(c.velocity, v_before);
}

/// VF and EE pairs (no shared vertex) that touch (δ = 0) during the linear motion from `x0` to
/// `x1`, every pair tried with the exact CCD: no broad phase, no continuous query.
std::size_t touching_pairs_by_brute_force(const Topology& topology, PositionsView x0, PositionsView x1) {
  const auto points = [&](const std::array<Index, 4>& v, geometry::CcdPoints& p0, geometry::CcdPoints& p1) {
    for (std::size_t k = 0; k < 4; ++k) {
      p0[k] = x0[static_cast<std::size_t>(v[k])];
      p1[k] = x1[static_cast<std::size_t>(v[k])];
    }
  };
  std::size_t count = 0;
  geometry::CcdPoints p0, p1;
  for (Index v = 0; v < topology.num_vertices(); ++v) {
    for (Index f = 0; f < topology.num_faces(); ++f) {
      const Face& face = topology.face(f);
      if (std::find(face.begin(), face.end(), v) != face.end()) continue;
      points({v, face[0], face[1], face[2]}, p0, p1);
      count += geometry::vertex_face_ccd(p0, p1).hit;
    }
  }
  const auto edges = topology.edges();
  for (std::size_t a = 0; a < edges.size(); ++a) {
    for (std::size_t b = a + 1; b < edges.size(); ++b) {
      const Edge& e = edges[a];
      const Edge& g = edges[b];
      if (e[0] == g[0] || e[0] == g[1] || e[1] == g[0] || e[1] == g[1]) continue;
      points({e[0], e[1], g[0], g[1]}, p0, p1);
      count += geometry::edge_edge_ccd(p0, p1).hit;
    }
  }
  return count;
}

/// The impulse stage with a continuous query after every round (no rounds on re-tested pairs):
/// Gauss–Seidel impulses on the live impacts (as `CcdFailSafe` defines them, no tangle) for at
/// most `rounds` rounds, each vertex an impulse touched moved to start + u. Returns whether the
/// last query was clean; `x` holds the corrected ends.
bool impulses_queried_every_round(std::shared_ptr<const Topology> topology, PositionsView start,
                                  std::span<const Scalar> inv_mass, std::span<Vec3> x, const FailSafeOptions& o,
                                  int rounds) {
  ContinuousQuery query(topology, [&] {
    ContinuousOptions q = o.query;
    q.min_separation = o.min_separation;
    return q;
  }());
  geometry::CcdOptions touching = o.query.narrow;
  touching.min_separation = 0;
  const auto live = [&] {
    ImpactSet impacts;
    query.query(start, PositionsView(x.data(), x.size()), impacts);
    std::vector<Stencil> out;
    const auto keep = [&](Stencil s, geometry::CcdPair kind, Scalar toi, Scalar distance) {
      if (toi == 0 && distance <= o.min_separation) {
        geometry::CcdPoints p0, p1;
        for (std::size_t k = 0; k < 4; ++k) {
          p0[k] = start[static_cast<std::size_t>(s.vertex[k])];
          p1[k] = x[static_cast<std::size_t>(s.vertex[k])];
        }
        if (!geometry::ccd(kind, p0, p1, touching).hit) return;
      }
      out.push_back(s);
    };
    for (const VertexFaceImpact& c : impacts.vf) {
      keep(vertex_face_stencil(c.vertex, topology->face(c.face), c.barycentric, c.normal),
           geometry::CcdPair::kVertexFace, c.toi, c.distance);
    }
    for (const EdgeEdgeImpact& c : impacts.ee) {
      keep(edge_edge_stencil(c.a, c.b, c.s, c.t, c.normal), geometry::CcdPair::kEdgeEdge, c.toi, c.distance);
    }
    return out;
  };
  std::vector<Vec3> u(x.size());
  for (std::size_t i = 0; i < x.size(); ++i) u[i] = x[i] - start[i];
  std::vector<Stencil> pairs = live();
  for (int r = 0; r < rounds && !pairs.empty(); ++r) {
    for (const Stencil& s : pairs) {
      if (s.normal.squaredNorm() > 0 && correct_velocity(s, inv_mass, u) > 0) {
        for (int k = 0; k < s.count; ++k) {
          const auto v = static_cast<std::size_t>(s.vertex[static_cast<std::size_t>(k)]);
          x[v] = start[v] + u[v];
        }
      }
    }
    pairs = live();
  }
  return pairs.empty();
}

// Issue 43: once a query returns the pairs of the query before, the impulse rounds run on those
// pairs alone, re-tested by the narrow phase each round instead of queried. Two triangles less
// than δ apart, one pressed into the other with a random tilt and slide: some frames take that
// path (`retested_rounds`). Each must keep the guarantee (no pair touches, every pair tried, no
// face pair intersects), give the same bits with restricted queries or full ones, and, where
// impulses alone settle it, the same bits as impulse rounds with a query after each: a re-tested
// pair's stencil is the one the query would give (same narrow phase, same formulas), so rounds on
// the pairs alone differ from queried rounds only when a query would have found a new pair.
TEST(FailSafe, RoundsOnRepeatedPairsKeepTheGuaranteeAndTheQueriedRounds) {
  const int kSeeds = 2000;  // ~0.25 s: most frames are settled by one query or two
  int retested = 0, settled = 0;
  for (int seed = 1; seed <= kSeeds; ++seed) {
    std::mt19937_64 rng(static_cast<std::uint64_t>(seed));
    std::uniform_real_distribution<Scalar> d(-1, 1);
    const Scalar delta = 0.01;
    Positions start{Vec3(0, 0, 0),   Vec3(1, 0, 0),   Vec3(0, 1, 0),
                    Vec3(0.2, 0.2, 0), Vec3(0.9, 0.2, 0), Vec3(0.2, 0.9, 0)};
    const Scalar gap = delta * (0.6 + 0.6 * d(rng));  // B above A, within δ at places
    for (std::size_t i = 3; i < 6; ++i) start[i].z() = gap + 0.3 * delta * (d(rng) + 1);
    const auto topology = TriMesh::create(start, {Face{0, 1, 2}, Face{3, 4, 5}}).topology_ptr();
    Positions proposed = start;
    for (Vec3& p : proposed) p += 0.05 * Vec3(d(rng), d(rng), d(rng));
    for (std::size_t i = 3; i < 6; ++i) proposed[i].z() -= 0.05 * (d(rng) + 1);  // B pressed down
    std::vector<Scalar> inv_mass(6, 1);
    if (seed % 2 == 1) inv_mass[0] = inv_mass[1] = inv_mass[2] = 0;  // A pinned: a wall
    FailSafeOptions o = options(20, 8);
    o.min_separation = delta;
    FailSafeStats stats[2];
    Positions end[2], velocity[2];
    for (const bool restrict : {false, true}) {
      o.restrict_queries = restrict;
      CcdFailSafe safe(topology, o);
      end[restrict] = proposed;
      velocity[restrict] = Positions(6, Vec3::Zero());
      stats[restrict] = safe.apply(start, inv_mass, 1.0 / 60, end[restrict], velocity[restrict]);
    }
    if (stats[1].retested_rounds == 0) continue;
    ++retested;
    SCOPED_TRACE(::testing::Message() << "seed " << seed);
    ASSERT_EQ(testing::exact_intersections(*topology, start).disjoint, 0u);
    EXPECT_EQ(touching_pairs_by_brute_force(*topology, start, end[1]), 0u);
    EXPECT_EQ(testing::exact_intersections(*topology, end[1]).disjoint, 0u);
    EXPECT_EQ(stats[0].retested_rounds, stats[1].retested_rounds);
    EXPECT_EQ(stats[0].impulse_rounds, stats[1].impulse_rounds);
    EXPECT_TRUE(end[0] == end[1]) << "restricted queries changed the correction";
    EXPECT_TRUE(velocity[0] == velocity[1]);
    Positions reference = proposed;
    if (!impulses_queried_every_round(topology, start, inv_mass, reference, o, o.impulse_rounds)) continue;
    ++settled;
    EXPECT_EQ(stats[1].zone_rounds, 0);
    EXPECT_EQ(stats[1].frozen, 0u);
    EXPECT_TRUE(end[1] == reference) << "rounds on the re-tested pairs differ from rounds with a query each";
  }
  // 23 and 8 of them with libstdc++'s distributions.
  EXPECT_GE(retested, 10) << "too few frames ran rounds on re-tested pairs";
  EXPECT_GE(settled, 4) << "too few of them were settled by impulses alone";
}

// `queries` counts the continuous queries that ran; a check that finds no end moved since the
// last query reuses its answer and counts in `unchanged`. A second apply from the same start
// with the corrected ends runs no query at all; full queries (restrict_queries off) run one for
// every check, the same count as queries + unchanged.
TEST(FailSafe, QueriesCountOnlyQueriesThatRan) {
  for (const bool restrict : {false, true}) {
    SCOPED_TRACE(restrict ? "restricted queries" : "full queries");
    Crossing c;
    FailSafeOptions o = options(3, 8);
    o.restrict_queries = restrict;
    CcdFailSafe safe(c.topology, o);
    const FailSafeStats first = safe.apply(c.start, c.inv_mass, 0.1, c.end, c.velocity);
    EXPECT_GT(first.impacts, 0u);
    EXPECT_GE(first.queries, 2);
    const Positions corrected = c.end;
    const FailSafeStats again = safe.apply(c.start, c.inv_mass, 0.1, c.end, c.velocity);
    EXPECT_EQ(again.impacts, 0u);
    EXPECT_EQ(c.end, corrected);
    EXPECT_EQ(again.queries + again.unchanged, 1);
    EXPECT_EQ(again.queries, restrict ? 0 : 1) << "no end moved: the last query's answer stands";
  }
  // All pinned: the impulse round moves nothing, so its check needs no query.
  FailSafeStats stats[2];
  for (const bool restrict : {false, true}) {
    Crossing c;
    std::fill(c.inv_mass.begin(), c.inv_mass.end(), 0);
    FailSafeOptions o = options(20, 8);
    o.restrict_queries = restrict;
    CcdFailSafe safe(c.topology, o);
    stats[restrict] = safe.apply(c.start, c.inv_mass, 0.1, c.end, c.velocity);
  }
  EXPECT_EQ(stats[0].unchanged, 0);
  EXPECT_GT(stats[1].unchanged, 0);
  EXPECT_EQ(stats[1].queries + stats[1].unchanged, stats[0].queries);
}

/// Two triangles around the edges (a0, a1) and (b0, b1) of `start` → `end` (points 0..3), each
/// closed by a third corner 5 mm away from the other edge, moving with its edge's midpoint.
struct EdgePair {
  Positions start, end;
  std::shared_ptr<const Topology> topology;
  EdgePair(const std::array<Vec3, 4>& x0, const std::array<Vec3, 4>& x1) {
    const auto third = [](const std::array<Vec3, 4>& x, int e) -> Vec3 {
      const Vec3 mid = 0.5 * (x[2 * e] + x[2 * e + 1]);
      const Vec3 other = 0.5 * (x[2 - 2 * e] + x[3 - 2 * e]);
      const Vec3 along = (x[2 * e + 1] - x[2 * e]).normalized();
      Vec3 away = mid - other;
      away -= away.dot(along) * along;
      return mid + 0.005 * away.normalized();
    };
    start = {x0[0], x0[1], third(x0, 0), x0[2], x0[3], third(x0, 1)};
    end = {x1[0], x1[1], third(x1, 0), x1[2], x1[3], third(x1, 1)};
    topology = TriMesh::create(start, {Face{0, 1, 2}, Face{3, 4, 5}}).topology_ptr();
  }
};

// Two sides of a border quad of `crumple:n=100` squeezed by the wall (frame 43, δ = 0.1 h_c),
// after a round of CCD impulses: the pair grazes at 1.009 δ, inside the band δ (1 + σ) where the
// query reports a hit (`kHitTolerance`, distance above δ) that it cannot certify away, and the
// impulses have no approach left to remove. It used to stay live through every impulse round,
// the zones and the fallback (15 queries a frame, its vertices frozen). Certified never to come
// within δ (1 − σ) it is not live. The same pair's proposed motion of frame 42, which the query
// also reports above δ at its time of impact, passes the edges through each other: live.
TEST(FailSafe, GrazingPairInsideTheQueryToleranceIsNotLive) {
  const Scalar delta = 0.00034114704261972739;
  const Scalar sigma = geometry::CcdOptions{}.separation_tolerance;
  const EdgePair grazing({Vec3(0.95387240187976541, 0.013136551171045714, 0.55658827080085493),
                          Vec3(0.95341425053995155, 0.020357946191875618, 0.56788390888035067),
                          Vec3(0.95387240187976541, 0.02333935362881976, 0.56036027982171044),
                          Vec3(0.95387240187976541, 0.01283154301157954, 0.57074527158727006)},
                         {Vec3(0.95265398237278598, 0.014863974247776073, 0.55694056951921733),
                          Vec3(0.95248568734665173, 0.020919373326510979, 0.56876992475191479),
                          Vec3(0.9529316694397949, 0.024654198787389867, 0.56018727340903451),
                          Vec3(0.95289409920716506, 0.013232649064506235, 0.56866950348844658)});
  const EdgePair crossing({Vec3(0.95762510773554643, 0.01085891701185349, 0.5600385733860721),
                           Vec3(0.95484001671300356, 0.014022799195538662, 0.56838850644864503),
                           Vec3(0.95970573521309877, 0.019320100563474767, 0.56810672269290019),
                           Vec3(0.95970573521309877, 0.0081942219820899248, 0.57531065347174448)},
                          {Vec3(0.958539068546432, 0.013264377076390603, 0.55869694131640024),
                           Vec3(0.958539068546432, 0.014252141034481148, 0.56970999765463126),
                           Vec3(0.95832277766827645, 0.022457458626362392, 0.55833748608618405),
                           Vec3(0.95367547795886731, 0.011766653562719137, 0.57007019673276649)});
  const auto points = [](const Positions& x) { return geometry::CcdPoints{x[0], x[1], x[3], x[4]}; };
  geometry::CcdOptions narrow;
  narrow.min_separation = delta;
  for (const EdgePair* pair : {&grazing, &crossing}) {
    const geometry::CcdResult r = geometry::ccd(geometry::CcdPair::kEdgeEdge, points(pair->start), points(pair->end), narrow);
    ASSERT_TRUE(r.hit);
    EXPECT_EQ(r.outcome, geometry::CcdOutcome::kHitTolerance);
    const EdgeEdgeImpact impact = edge_edge_impact(points(pair->start), points(pair->end), r);
    EXPECT_GT(impact.distance, delta) << "reported above δ, inside the tolerance band";
    EXPECT_LT(impact.distance, delta * (1 + sigma));
  }
  geometry::CcdOptions below = narrow;
  below.min_separation = delta * (1 - sigma);
  EXPECT_FALSE(geometry::ccd(geometry::CcdPair::kEdgeEdge, points(grazing.start), points(grazing.end), below).hit);
  EXPECT_GT(touching_pairs(crossing.topology, crossing.start, crossing.end), 0u) << "the edges pass through";

  FailSafeOptions o = options(20, 8);
  o.min_separation = delta;
  const std::vector<Scalar> inv_mass(6, 1);
  {
    Positions x = grazing.end, v(6, Vec3::Zero());
    CcdFailSafe safe(grazing.topology, o);
    const FailSafeStats stats = safe.apply(grazing.start, inv_mass, 1.0 / 60, x, v);
    EXPECT_EQ(stats.impacts, 0u);
    EXPECT_EQ(stats.queries, 1);
    EXPECT_EQ(x, grazing.end) << "the proposed motion stands";
  }
  {
    Positions x = crossing.end, v(6, Vec3::Zero());
    CcdFailSafe safe(crossing.topology, o);
    const FailSafeStats stats = safe.apply(crossing.start, inv_mass, 1.0 / 60, x, v);
    EXPECT_GT(stats.impacts, 0u);
    EXPECT_EQ(touching_pairs(crossing.topology, crossing.start, x), 0u);
  }
}

TEST(FailSafe, RejectsBadOptions) {
  Crossing c;
  FailSafeOptions o = options(3, 8);
  o.min_separation = -1;
  EXPECT_THROW(CcdFailSafe(c.topology, o), Error);
  o = options(-1, 8);
  EXPECT_THROW(CcdFailSafe(c.topology, o), Error);
}

/// Two 6 × 6 lattices in one mesh: the lower one in z = 0, the upper one shifted a little in x
/// and y and raised to z = gap + slope x (so that only a band of it is near the lower one).
struct Sheets {
  std::shared_ptr<const Topology> topology;
  Positions start;
};
Sheets two_sheets(Scalar gap, Scalar slope) {
  const TriMesh lattice = shapes::lattice(6, 6);
  Positions x = lattice.positions();
  const std::size_t nv = x.size();
  const auto lower = lattice.topology().faces();
  std::vector<Face> faces(lower.begin(), lower.end());
  for (std::size_t i = 0; i < nv; ++i) x.push_back(x[i] + Vec3(0.031, 0.017, gap + slope * x[i].x()));
  for (const Face& f : lower) {
    const auto up = [&](Index v) { return static_cast<Index>(static_cast<std::size_t>(v) + nv); };
    faces.push_back({up(f[0]), up(f[1]), up(f[2])});
  }
  const TriMesh mesh = TriMesh::create(x, faces);
  return {mesh.topology_ptr(), x};
}

/// The pairs within `radius` of each other at the sheets' start (the naive detector).
ContactSet pairs_within(const Sheets& sheets, Scalar radius) {
  auto detector = make_detector(MethodSpec::parse("naive"), {.thickness = radius, .threads = 1});
  detector->set_topology(sheets.topology);
  ContactSet near;
  detector->update(sheets.start, near);
  return near;
}

// The first query restricted by the start's proximity (`StartProximity`: the pairs within R at
// the start, here from the naive detector) has the full query's impacts, so the whole
// correction is the same, bit for bit. The frames exercise both halves of the argument: a band
// of the upper sheet within R of the lower one sinks through it too slowly for any vertex to be
// flagged as fast (only the near pairs' own test flags them: without it the restricted query
// finds nothing), a lone vertex of a sheet farther than R plunges through the other (only the
// fast flag finds it), and random jitters of both sheets of every size around s/2.
TEST(FailSafe, FirstQueryRestrictedByTheStartProximityGivesTheSameCorrection) {
  const Scalar radius = 0.1;
  struct Frame {
    const char* what;
    Scalar gap, slope;
    std::function<void(std::size_t, Vec3&, std::mt19937_64&)> move;  // (vertex, end, rng)
  };
  const std::size_t nv = 49;  // per sheet
  const std::vector<Frame> frames{
      {"near band sinks slowly", 0.05, 0.3, [&](std::size_t i, Vec3& x, std::mt19937_64&) { if (i >= nv) x.z() -= 0.07; }},
      {"far vertex plunges", 0.15, 0, [&](std::size_t i, Vec3& x, std::mt19937_64&) { if (i == nv + 24) x.z() -= 0.3; }},
      {"jitter 0.02", 0.06, 0.1, [&](std::size_t, Vec3& x, std::mt19937_64& rng) {
         std::uniform_real_distribution<Scalar> d(-0.02, 0.02);
         x += Vec3(d(rng), d(rng), d(rng));
       }},
      {"jitter 0.05", 0.06, 0.1, [&](std::size_t, Vec3& x, std::mt19937_64& rng) {
         std::uniform_real_distribution<Scalar> d(-0.05, 0.05);
         x += Vec3(d(rng), d(rng), d(rng));
       }},
      {"jitter 0.1", 0.12, 0, [&](std::size_t, Vec3& x, std::mt19937_64& rng) {
         std::uniform_real_distribution<Scalar> d(-0.1, 0.1);
         x += Vec3(d(rng), d(rng), d(rng));
       }},
  };
  int with_impacts = 0, partly_flagged = 0;
  for (const Frame& frame : frames) {
    for (std::uint64_t seed = 1; seed <= 4; ++seed) {
      SCOPED_TRACE(::testing::Message() << frame.what << ", seed " << seed);
      const Sheets sheets = two_sheets(frame.gap, frame.slope);
      const Positions& start = sheets.start;
      std::mt19937_64 rng(seed);
      Positions proposed = start;
      for (std::size_t i = 0; i < proposed.size(); ++i) frame.move(i, proposed[i], rng);
      std::vector<Scalar> inv_mass(start.size(), 1);
      const ContactSet near = pairs_within(sheets, radius);
      const StartProximity proximity{radius, &near};
      FailSafeStats stats[2];
      Positions end[2], velocity[2];
      for (const bool seeded : {false, true}) {
        FailSafeOptions o = options(3, 8);
        o.min_separation = 0.01;
        o.restricted_share = 1;  // restricted however many vertices it flags
        CcdFailSafe safe(sheets.topology, o);
        end[seeded] = proposed;
        velocity[seeded] = Positions(start.size(), Vec3::Zero());
        stats[seeded] = safe.apply(start, inv_mass, 1.0 / 60, end[seeded], velocity[seeded],
                                   seeded ? &proximity : nullptr);
        EXPECT_EQ(touching_pairs(sheets.topology, start, end[seeded]), 0u);
      }
      EXPECT_FALSE(stats[0].first_restricted);
      EXPECT_TRUE(stats[1].first_restricted);
      with_impacts += stats[0].impacts > 0 ? 1 : 0;
      partly_flagged += stats[1].first_flagged < start.size() ? 1 : 0;
      EXPECT_EQ(stats[1].impacts, stats[0].impacts);
      EXPECT_EQ(stats[1].queries + stats[1].unchanged, stats[0].queries + stats[0].unchanged);
      EXPECT_EQ(stats[1].zone_vertices, stats[0].zone_vertices);
      EXPECT_EQ(stats[1].frozen, stats[0].frozen);
      EXPECT_TRUE(end[1] == end[0]) << "the corrected ends differ";
      EXPECT_TRUE(velocity[1] == velocity[0]) << "the corrected velocities differ";
      if (frame.gap == 0.05 || frame.gap == 0.15) {
        EXPECT_GT(stats[0].impacts, 0u) << "the frame must pass a sheet through the other";
        EXPECT_LT(stats[1].first_flagged, start.size() / 2) << "the restriction must leave most vertices out";
      }
    }
  }
  EXPECT_GE(with_impacts, 14) << "most frames (of 20) must have impacts";
  EXPECT_GE(partly_flagged, 12) << "most restricted queries must leave vertices out";
}

// The motion bound (`FailSafeOptions::motion_bound`): the first query leaves out the pairs that
// move together (relative displacement within s, no exempt vertex). Both sheets fall farther
// than R in the frame, the upper one faster, through the lower one (they start farther apart
// than R, so nothing is listed and no vertex exempt): only the relative motion of the sheets
// tells these pairs from those within each sheet. Then a band of the upper sheet, listed near
// the lower one, sinks through it while both fall (exempt by its own test, its relative motion
// within s). Either way the same correction as the sweep's and as the restriction without the
// bound, bit for bit, restricted to the fast sheet or sweeping the mesh; a bound that left out a pair moving apart by more than s, or that
// ignored the exempt flags, misses the crossing.
TEST(FailSafe, FirstQueryLeavesOutPairsThatMoveTogether) {
  const Scalar radius = 0.1;
  const std::size_t nv = 49;  // per sheet
  struct Frame {
    const char* what;
    Scalar gap, slope, fall, extra;  // both sheets fall by `fall`, the upper's band by `extra` more
  };
  for (const Frame& frame : {Frame{"the upper sheet falls through the lower", 0.15, 0, 0.3, 0.25},
                             Frame{"a near band sinks through while both fall", 0.05, 0.3, 0.3, 0.07}}) {
    for (const Scalar jitter : {0.0, 0.004}) {
      SCOPED_TRACE(::testing::Message() << frame.what << ", jitter " << jitter);
      const Sheets sheets = two_sheets(frame.gap, frame.slope);
      const Positions& start = sheets.start;
      Positions proposed = start;
      std::mt19937_64 rng(7);
      std::uniform_real_distribution<Scalar> d(-jitter, jitter);
      for (std::size_t i = 0; i < proposed.size(); ++i) {
        proposed[i].z() -= frame.fall + (i >= nv ? frame.extra : 0);
        proposed[i] += Vec3(d(rng), d(rng), d(rng));
      }
      std::vector<Scalar> inv_mass(start.size(), 1);
      const ContactSet near = pairs_within(sheets, radius);
      const StartProximity proximity{radius, &near};
      FailSafeStats stats[4];
      Positions end[4], velocity[4];
      for (int run = 0; run < 4; ++run) {  // the sweep; restricted without the bound, with it; the sweep with it
        FailSafeOptions o = options(3, 8);
        o.min_separation = 0.01;
        o.restricted_share = run == 3 ? 0 : 1;
        o.motion_bound = run >= 2;
        CcdFailSafe safe(sheets.topology, o);
        end[run] = proposed;
        velocity[run] = Positions(start.size(), Vec3::Zero());
        stats[run] = safe.apply(start, inv_mass, 1.0 / 60, end[run], velocity[run], run > 0 ? &proximity : nullptr);
        EXPECT_EQ(touching_pairs(sheets.topology, start, end[run]), 0u) << "run " << run;
      }
      EXPECT_GT(stats[0].impacts, 0u) << "the frame must pass a sheet through the other";
      EXPECT_FALSE(stats[0].first_restricted);
      EXPECT_TRUE(stats[2].first_restricted);
      EXPECT_FALSE(stats[3].first_restricted);
      for (int run = 1; run < 4; ++run) {
        EXPECT_EQ(stats[run].impacts, stats[0].impacts) << "run " << run;
        EXPECT_EQ(stats[run].queries + stats[run].unchanged, stats[0].queries + stats[0].unchanged);
        EXPECT_EQ(stats[run].frozen, stats[0].frozen);
        EXPECT_TRUE(end[run] == end[0]) << "run " << run << ": the corrected ends differ";
        EXPECT_TRUE(velocity[run] == velocity[0]) << "run " << run << ": the corrected velocities differ";
      }
    }
  }
}

// A start proximity that cannot bound the motion (a radius at or below δ (1 + σ)) leaves the
// first query a sweep of the mesh.
TEST(FailSafe, StartProximityWithinTheSeparationIsNotUsed) {
  const Sheets sheets = two_sheets(0.05, 0);
  Positions end = sheets.start, velocity(end.size(), Vec3::Zero());
  for (std::size_t i = 49; i < end.size(); ++i) end[i].z() -= 0.1;
  ContactSet near;  // nothing within the radius claimed: would be wrong at any larger radius
  const StartProximity proximity{0.01, &near};
  FailSafeOptions o = options(3, 8);
  o.min_separation = 0.01;
  CcdFailSafe safe(sheets.topology, o);
  const FailSafeStats stats =
      safe.apply(sheets.start, std::vector<Scalar>(end.size(), 1), 1.0 / 60, end, velocity, &proximity);
  EXPECT_FALSE(stats.first_restricted);
  EXPECT_GT(stats.impacts, 0u);
  EXPECT_EQ(touching_pairs(sheets.topology, sheets.start, end), 0u);
}

}  // namespace
}  // namespace crumple::response
