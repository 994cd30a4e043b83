// The continuous query restricted to flagged ("moved") vertices (ContinuousQuery::query_moved,
// update_moved): exactly the full query's impacts whose pair holds a flagged vertex, every
// field bit for bit and in the same order, for every broad phase and thread count; and a full
// query updated after some vertices' ends moved equals the full query of the new motion. On
// seeded lattices with random motion, a star with a lone vertex, and real frame pairs.
#include <crumple/core/error.hpp>
#include <crumple/detect/continuous.hpp>
#include <crumple/io/mesh_io.hpp>
#include <crumple/mesh/shapes.hpp>
#include <support/meshes.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <limits>
#include <memory>
#include <numbers>
#include <random>
#include <string>
#include <vector>

namespace crumple {
namespace {

bool same_bits(Scalar a, Scalar b) { return std::memcmp(&a, &b, sizeof a) == 0; }
bool same_bits(const Vec3& a, const Vec3& b) { return std::memcmp(a.data(), b.data(), sizeof(Vec3)) == 0; }

bool same(const VertexFaceImpact& a, const VertexFaceImpact& b) {
  return a.vertex == b.vertex && a.face == b.face && same_bits(a.toi, b.toi) && same_bits(a.distance, b.distance) &&
         same_bits(a.barycentric, b.barycentric) && same_bits(a.normal, b.normal) && a.outcome == b.outcome;
}
bool same(const EdgeEdgeImpact& a, const EdgeEdgeImpact& b) {
  return a.edge0 == b.edge0 && a.edge1 == b.edge1 && a.a == b.a && a.b == b.b && same_bits(a.toi, b.toi) &&
         same_bits(a.distance, b.distance) && same_bits(a.s, b.s) && same_bits(a.t, b.t) &&
         same_bits(a.normal, b.normal) && a.outcome == b.outcome;
}

/// Whether the two sets hold the same impacts in the same order, every field bit for bit.
::testing::AssertionResult identical(const ImpactSet& got, const ImpactSet& want) {
  if (got.vf.size() != want.vf.size() || got.ee.size() != want.ee.size()) {
    return ::testing::AssertionFailure() << got.vf.size() << " VF and " << got.ee.size() << " EE impacts, expected "
                                         << want.vf.size() << " and " << want.ee.size();
  }
  for (std::size_t i = 0; i < got.vf.size(); ++i) {
    if (!same(got.vf[i], want.vf[i])) {
      return ::testing::AssertionFailure() << "VF " << i << ": vertex " << got.vf[i].vertex << " face "
                                           << got.vf[i].face << ", expected vertex " << want.vf[i].vertex << " face "
                                           << want.vf[i].face << " (or a field differs)";
    }
  }
  for (std::size_t i = 0; i < got.ee.size(); ++i) {
    if (!same(got.ee[i], want.ee[i])) {
      return ::testing::AssertionFailure() << "EE " << i << ": edges " << got.ee[i].edge0 << ' ' << got.ee[i].edge1
                                           << ", expected " << want.ee[i].edge0 << ' ' << want.ee[i].edge1
                                           << " (or a field differs)";
    }
  }
  return ::testing::AssertionSuccess();
}

/// The impacts of `all` whose pair holds a flagged vertex (the oracle, from the full query).
ImpactSet flagged_only(const Topology& topo, const ImpactSet& all, const std::vector<char>& moved) {
  const auto f = [&](Index v) { return moved[static_cast<std::size_t>(v)] != 0; };
  ImpactSet out;
  for (const auto& i : all.vf) {
    const Face& t = topo.face(i.face);
    if (f(i.vertex) || f(t[0]) || f(t[1]) || f(t[2])) out.vf.push_back(i);
  }
  for (const auto& i : all.ee) {
    if (f(i.a[0]) || f(i.a[1]) || f(i.b[0]) || f(i.b[1])) out.ee.push_back(i);
  }
  return out;
}

std::vector<char> random_flags(std::size_t n, double fraction, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::vector<char> flags(n, 0);
  for (char& c : flags) c = static_cast<char>((rng() >> 11) * 0x1.0p-53 < fraction);
  return flags;
}

/// Counts of what one comparison saw: flagged impacts and all impacts of the full query.
struct Seen {
  std::size_t flagged = 0, all = 0;
  std::size_t changed = 0;  ///< updates where the moved ends changed the impacts
};

/// query_moved against the filtered full query for every broad phase, thread count and each
/// flag set; then update_moved: the full query of (x0, x1) with the flagged vertices' ends
/// moved to `x1_moved` equals the earlier full query updated at the flagged vertices.
Seen check(const std::string& name, const std::shared_ptr<const Topology>& topo, PositionsView x0, PositionsView x1,
           PositionsView x1_moved, Scalar delta, const std::vector<std::vector<char>>& flag_sets) {
  Seen seen;
  for (const char* spec : {"kdop", "hash", "sap"}) {
    for (const int threads : {1, 3}) {
      SCOPED_TRACE(name + " " + spec + " threads " + std::to_string(threads) + " delta " + std::to_string(delta));
      ContinuousOptions options;
      options.min_separation = delta;
      options.method = MethodSpec::parse(spec);
      options.threads = threads;
      ContinuousQuery query(topo, options);
      ImpactSet full, got;
      query.query(x0, x1, full);
      for (const auto& moved : flag_sets) {
        const ImpactSet want = flagged_only(*topo, full, moved);
        query.query_moved(x0, x1, moved, got);
        EXPECT_TRUE(identical(got, want));
        seen.flagged += want.size();
        seen.all += full.size();

        // The motion changed at the flagged vertices only.
        Positions x1_new(x1.begin(), x1.end());
        for (std::size_t v = 0; v < x1_new.size(); ++v) {
          if (moved[v]) x1_new[v] = x1_moved[v];
        }
        ImpactSet updated = full, fresh;
        query.update_moved(x0, x1_new, moved, updated);
        query.query(x0, x1_new, fresh);
        EXPECT_TRUE(identical(updated, fresh)) << "update_moved";
        seen.changed += identical(full, fresh) ? 0 : 1;
      }
    }
  }
  return seen;
}

TEST(ContinuousMoved, LatticesWithRandomMotionMatchTheFullQuery) {
  Seen seen;
  for (const std::uint64_t seed : {1u, 2u}) {
    const TriMesh mesh = shapes::lattice(9, 8);
    const auto topo = mesh.topology_ptr();
    const Positions x0 = testing::crumple_lattice(mesh, 0.15, seed);
    const Positions x1 = testing::jitter(testing::crumple_lattice(mesh, 0.25, seed + 10), 0.12, seed + 20);
    const Positions x1_moved = testing::jitter(x1, 0.1, seed + 30);
    const std::size_t n = x0.size();
    std::vector<std::vector<char>> flags{random_flags(n, 0.05, seed), random_flags(n, 0.3, seed + 1),
                                         std::vector<char>(n, 1)};
    for (const Scalar delta : {0.0, 0.02}) {
      const Seen s = check("lattice seed " + std::to_string(seed), topo, x0, x1, x1_moved, delta, flags);
      seen.flagged += s.flagged;
      seen.all += s.all;
      seen.changed += s.changed;
    }
  }
  // Non-vacuous: the flags pick some impacts, and not all of them.
  EXPECT_GT(seen.flagged, 100u);
  EXPECT_LT(seen.flagged, seen.all);
  EXPECT_EQ(seen.changed, 2u * 2u * 3u * 6u) << "every update must change the impacts, or it proves little";
}

// The restricted query keeps its tree of every face across calls and refits it where vertices
// moved: over a sequence of motions from one query object, each changing the start or the end
// of a few vertices (as a fail-safe's rounds and frames do), every restricted query still
// equals the full query of its own motion filtered to its flags.
TEST(ContinuousMoved, ASequenceOfMotionsMatchesTheFullQueryAtEveryStep) {
  const TriMesh mesh = shapes::lattice(12, 11);
  const auto topo = mesh.topology_ptr();
  Positions x0 = testing::crumple_lattice(mesh, 0.15, 41);
  Positions x1 = testing::jitter(testing::crumple_lattice(mesh, 0.25, 42), 0.12, 43);
  const std::size_t n = x0.size();
  std::mt19937_64 rng(44);
  std::size_t flagged = 0, all = 0, changed = 0;
  for (const int threads : {1, 3}) {
    SCOPED_TRACE("threads " + std::to_string(threads));
    ContinuousOptions options;
    options.min_separation = 0.02;
    options.threads = threads;
    ContinuousQuery query(topo, options);
    ImpactSet last;
    for (int step = 0; step < 12; ++step) {
      // A few starts (even steps) or ends (odd steps) move, far enough to change the impacts.
      const std::vector<char> move = random_flags(n, 0.06, 100 + static_cast<std::uint64_t>(step));
      Positions& x = step % 2 == 0 ? x0 : x1;
      const Positions moved_to = testing::jitter(x, 0.15, 200 + static_cast<std::uint64_t>(step));
      for (std::size_t v = 0; v < n; ++v) {
        if (move[v]) x[v] = moved_to[v];
      }
      const std::vector<char> flags = random_flags(n, step % 3 == 0 ? 0.5 : 0.1, 300 + static_cast<std::uint64_t>(step));
      ImpactSet full, got;
      query.query_moved(x0, x1, flags, got);  // before the full query: the tree is the restricted query's own
      query.query(x0, x1, full);
      const ImpactSet want = flagged_only(*topo, full, flags);
      EXPECT_TRUE(identical(got, want)) << "step " << step;
      flagged += want.size();
      all += full.size();
      changed += identical(full, last) ? 0 : 1;
      last = full;
    }
  }
  EXPECT_GT(flagged, 100u);
  EXPECT_LT(flagged, all);
  EXPECT_EQ(changed, 24u) << "every step must change the impacts, or it proves little";
}

TEST(ContinuousMoved, NoFlagGivesNoImpactAndWrongSizesThrow) {
  const TriMesh mesh = shapes::lattice(6, 6);
  const auto topo = mesh.topology_ptr();
  const Positions x0 = testing::crumple_lattice(mesh, 0.15, 3);
  const Positions x1 = testing::jitter(testing::crumple_lattice(mesh, 0.25, 13), 0.12, 23);
  ContinuousQuery query(topo, {});
  ImpactSet full, got;
  query.query(x0, x1, full);
  ASSERT_GT(full.size(), 0u);
  query.query_moved(x0, x1, std::vector<char>(x0.size(), 0), got);
  EXPECT_TRUE(got.empty());
  EXPECT_THROW(query.query_moved(x0, x1, std::vector<char>(x0.size() - 1, 1), got), InputError);
  EXPECT_THROW(query.update_moved(x0, x1, std::vector<char>(x0.size() + 1, 1), full), InputError);
  EXPECT_TRUE(full.empty());
}

// A two-turn fan around a star (more than 64 faces: its orphans found each step) crossing
// itself, and a vertex of no face dropping through it; flags on the rim, on the centre only
// and on the lone vertex only.
// The motion bound (`ContinuousQuery::MotionBound`): of the flagged impacts of the full query,
// every one with an exempt vertex or a relative displacement above the reach is kept, bit for
// bit and in order, and nothing else is added; likewise the sweep with the bound (`query`, every
// vertex flagged: its face pairs and its orphans around calm vertices dropped). Half of a crumpled lattice falls as one (its
// near pairs, within δ, move together and may be left out), the rest jitters; random exempt
// flags; the reach below and above the jitter. A bound that compared the displacement boxes'
// nearest points instead of their farthest fails it.
TEST(ContinuousMoved, AMotionBoundLeavesOutOnlyPairsThatMoveTogether) {
  const TriMesh mesh = shapes::lattice(12, 11);
  const auto topo = mesh.topology_ptr();
  const std::size_t n = mesh.positions().size();
  std::size_t left_out = 0, kept_apart = 0, kept_exempt = 0, sweep_left_out = 0;
  for (const std::uint64_t seed : {1u, 2u}) {
    const Positions x0 = testing::crumple_lattice(mesh, 0.15, seed);
    Positions x1 = testing::jitter(x0, 0.04, seed + 10);
    for (std::size_t v = 0; v < n; ++v) {
      if (mesh.positions()[v].x() < 0.5) x1[v] = x0[v] + Vec3(0.01, -0.02, -0.3);
    }
    const std::vector<char> exempt = random_flags(n, 0.05, seed + 20);
    const auto u = [&](Index v) { return x1[static_cast<std::size_t>(v)] - x0[static_cast<std::size_t>(v)]; };
    // The largest |uᵢ − uⱼ| over i in [0, first_b), j in [first_b, 4), and whether one is exempt.
    const auto apart = [&](const std::array<Index, 4>& v, std::size_t first_b, Scalar reach) {
      Scalar most = 0;
      for (std::size_t i = 0; i < first_b; ++i) {
        for (std::size_t j = first_b; j < 4; ++j) most = std::max(most, (u(v[i]) - u(v[j])).norm());
      }
      return most > reach * (1 + 1e-12);
    };
    const auto is_exempt = [&](const std::array<Index, 4>& v) {
      return exempt[static_cast<std::size_t>(v[0])] || exempt[static_cast<std::size_t>(v[1])] ||
             exempt[static_cast<std::size_t>(v[2])] || exempt[static_cast<std::size_t>(v[3])];
    };
    for (const int threads : {1, 3}) {
      ContinuousOptions options;
      options.min_separation = 0.02;
      options.threads = threads;
      ContinuousQuery query(topo, options);
      ImpactSet full, got;
      query.query(x0, x1, full);
      for (const int mode : {0, 1, 2}) {  // query_moved with every flag, with some; the sweep
        const std::vector<char> moved = mode == 1 ? random_flags(n, 0.3, seed + 30) : std::vector<char>(n, 1);
        const ImpactSet want = flagged_only(*topo, full, moved);
        for (const Scalar reach : {0.01, 0.05}) {
          SCOPED_TRACE(::testing::Message() << "seed " << seed << " threads " << threads << " reach " << reach
                                            << " mode " << mode);
          if (mode == 2) {
            query.query(x0, x1, {exempt, reach}, got);
          } else {
            query.query_moved(x0, x1, moved, {exempt, reach}, got);
          }
          // `got` is a subsequence of `want`, bit for bit, holding every impact that must stay.
          const auto check = [&](const auto& have, const auto& all, const auto& vertices, std::size_t first_b) {
            std::size_t k = 0;
            for (const auto& impact : all) {
              const std::array<Index, 4> v = vertices(impact);
              const bool must = is_exempt(v) || apart(v, first_b, reach);
              if (k < have.size() && same(have[k], impact)) {
                ++k;
                kept_apart += apart(v, first_b, reach) ? 1 : 0;
                kept_exempt += is_exempt(v) ? 1 : 0;
              } else {
                EXPECT_FALSE(must) << "an impact that moves apart or has an exempt vertex is missing";
                ++left_out;
              }
            }
            EXPECT_EQ(k, have.size()) << "an impact not in the query's, or out of order";
          };
          check(got.vf, want.vf, [&](const VertexFaceImpact& i) {
            const Face& t = topo->face(i.face);
            return std::array<Index, 4>{i.vertex, t[0], t[1], t[2]};
          }, 1);
          check(got.ee, want.ee, [](const EdgeEdgeImpact& i) { return std::array<Index, 4>{i.a[0], i.a[1], i.b[0], i.b[1]}; }, 2);
          if (mode == 2) sweep_left_out += want.size() - got.size();
        }
      }
    }
  }
  // Non-vacuous: pairs left out, and kept both for their motion and for their exempt flags.
  EXPECT_GT(left_out, 50u);
  EXPECT_GT(sweep_left_out, 20u);
  EXPECT_GT(kept_apart, 50u);
  EXPECT_GT(kept_exempt, 5u);
  // Bad flags or reach.
  ContinuousQuery query(topo, {});
  ImpactSet out;
  const Positions x0 = mesh.positions();
  EXPECT_THROW(query.query_moved(x0, x0, std::vector<char>(n, 1), {std::vector<char>(n - 1, 0), 0.1}, out), InputError);
  const std::vector<char> none(n, 0);
  EXPECT_THROW(query.query_moved(x0, x0, std::vector<char>(n, 1), {none, -1.0}, out), InputError);
  EXPECT_THROW(query.query(x0, x0, {std::vector<char>(n + 1, 0), 0.1}, out), InputError);
  EXPECT_THROW(query.query(x0, x0, {none, std::numeric_limits<Scalar>::infinity()}, out), InputError);
}

TEST(ContinuousMoved, StarsAndLoneVerticesMatchTheFullQuery) {
  const Index n = 160;
  Positions x0, x1, x1_moved;
  for (Index k = 0; k <= n; ++k) {
    const Scalar a = 4 * std::numbers::pi * static_cast<Scalar>(k) / static_cast<Scalar>(n);
    const Scalar turn = k * 2 < n ? 0 : 1;
    x0.emplace_back(std::cos(a), std::sin(a), 0.05 * turn);
    x1.emplace_back(std::cos(a), std::sin(a), -0.05 * turn);
    x1_moved.emplace_back(std::cos(a), std::sin(a), -0.08 * turn);
  }
  x0.emplace_back(0, 0, 0);
  x1.emplace_back(0, 0, 0);
  x1_moved.emplace_back(0, 0, -0.01);
  x0.emplace_back(0.5, 0.1, 0.3);  // used by no face: drops through the fan
  x1.emplace_back(0.5, 0.1, -0.3);
  x1_moved.emplace_back(0.52, 0.1, -0.3);
  std::vector<Face> faces;
  for (Index k = 0; k < n; ++k) faces.push_back({k, k + 1, n + 1});
  const TriMesh mesh = TriMesh::create(x0, faces);
  const std::size_t nv = x0.size();
  std::vector<char> rim = random_flags(nv, 0.1, 5), centre(nv, 0), lone(nv, 0);
  rim[static_cast<std::size_t>(n + 1)] = 0;
  rim[static_cast<std::size_t>(n + 2)] = 0;
  rim[static_cast<std::size_t>(n)] = 1;  // the second turn's end moves
  centre[static_cast<std::size_t>(n + 1)] = 1;
  lone[static_cast<std::size_t>(n + 2)] = 1;
  const Seen seen = check("two-turn fan", mesh.topology_ptr(), x0, x1, x1_moved, 0.01, {rim, centre, lone});
  EXPECT_GT(seen.flagged, 0u);
  EXPECT_EQ(seen.changed, 3u * 6u) << "every update must change the impacts";
}

TEST(ContinuousMoved, RealFramePairsMatchTheFullQuery) {
  const TriMesh t0 = io::read_mesh(testing::data_path("ipc-toolkit-tests/thick-cloth/t0.ply"));
  const TriMesh t1 = io::read_mesh(testing::data_path("ipc-toolkit-tests/thick-cloth/t1.ply"));
  const Scalar diag = compute_bounds(t0.positions()).diagonal();
  const std::size_t n = t0.positions().size();
  const Positions x1_moved = testing::jitter(t1.positions(), 1e-2 * diag, 77);
  const Seen seen = check("thick-cloth", t0.topology_ptr(), t0.positions(), t1.positions(), x1_moved, 1e-2 * diag,
                          {random_flags(n, 0.02, 8), random_flags(n, 0.2, 9)});
  EXPECT_GT(seen.flagged, 0u);
  EXPECT_LT(seen.flagged, seen.all);
  EXPECT_GT(seen.changed, 0u) << "an update must change the impacts";
}

}  // namespace
}  // namespace crumple
