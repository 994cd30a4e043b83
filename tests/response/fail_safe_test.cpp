// The continuous fail-safe alone (`CcdFailSafe`): a frame whose proposed motion passes
// triangles through each other ends intersection-free, by each stage and by the whole.
#include <crumple/core/error.hpp>
#include <crumple/detect/detector.hpp>
#include <crumple/mesh/shapes.hpp>
#include <crumple/response/fail_safe.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
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

TEST(FailSafe, RejectsBadOptions) {
  Crossing c;
  FailSafeOptions o = options(3, 8);
  o.min_separation = -1;
  EXPECT_THROW(CcdFailSafe(c.topology, o), Error);
  o = options(-1, 8);
  EXPECT_THROW(CcdFailSafe(c.topology, o), Error);
}

}  // namespace
}  // namespace crumple::response
