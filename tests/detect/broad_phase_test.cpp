// Each broad phase alone against brute force (STYLE.md §10): on the test meshes and on seeded
// deformations, over a sequence of frames (the structures keep state across frames), for every
// parameter and several thread counts, the candidates must hold, each once as {min, max}, every
// pair of faces sharing no vertex that its contract asks for (broad_phase.hpp): for `hash` and
// `sap` every pair whose inflated boxes overlap; for `kdop`, whose k-DOPs are tighter than
// boxes, every pair within twice the radius (every intersecting pair when only intersections
// are asked, where normal cones may skip the rest).
#include <crumple/detect/broad_phase/broad_phase.hpp>
#include <crumple/detect/broad_phase/hash_grid.hpp>
#include <crumple/detect/broad_phase/kdop_tree.hpp>
#include <crumple/detect/broad_phase/sweep_prune.hpp>
#include <crumple/geometry/distance.hpp>
#include <crumple/geometry/triangle_intersection.hpp>
#include <crumple/io/mesh_io.hpp>
#include <crumple/mesh/shapes.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>
#include <map>
#include <numeric>
#include <tuple>
#include <memory>
#include <optional>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include "support/meshes.hpp"

namespace crumple {
namespace {

/// A named way to make a broad phase, and whether it reports every pair of overlapping boxes
/// (else every pair within twice the radius).
struct Maker {
  std::string name;
  std::function<std::unique_ptr<BroadPhase>()> make;
  bool boxes = false;
};

/// Every kdop parameter combination that changes the tree or its traversal, hash cells and
/// tables (automatic, small, large), every sweep-and-prune axis.
std::vector<Maker> every_broad_phase() {
  std::vector<Maker> out;
  for (const int k : {6, 14, 18, 26}) {
    for (const int arity : {2, 4, 8}) {
      for (const int leaf : {1, 5, 48, 64}) {
        KdopParams p;
        p.k = k;
        p.arity = arity;
        p.leaf = leaf;
        out.push_back({"kdop:k=" + std::to_string(k) + ",arity=" + std::to_string(arity) + ",leaf=" +
                           std::to_string(leaf),
                       [p] { return std::make_unique<KdopTree>(p); }});
      }
    }
  }
  for (const bool sweep : {false, true}) {
    for (const bool cones : {false, true}) {
      for (const bool coherence : {false, true}) {
        for (const double rebuild : {1.0, 2.0}) {
          KdopParams p;
          p.sweep = sweep;
          p.cones = cones;
          p.coherence = coherence;
          p.rebuild = rebuild;
          out.push_back({std::string("kdop:sweep=") + (sweep ? "on" : "off") + ",cones=" + (cones ? "on" : "off") +
                             ",coherence=" + (coherence ? "on" : "off") + ",rebuild=" + std::to_string(rebuild),
                         [p] { return std::make_unique<KdopTree>(p); }});
        }
      }
    }
  }
  // (A table of 1 bucket, or cells much smaller than the edges, make the grid quadratic.)
  for (const double cell : {0.0, 0.6, 1.0, 4.0}) {
    for (const std::uint64_t table : {0u, 7u, 4099u}) {
      HashParams p;
      p.cell = cell;
      p.table = table;
      out.push_back({"hash:cell=" + std::to_string(cell) + ",table=" + std::to_string(table),
                     [p] { return std::make_unique<HashGrid>(p); }, true});
    }
  }
  for (const int axis : {-1, 0, 1, 2}) {
    SapParams p;
    p.axis = axis;
    out.push_back({"sap:axis=" + std::to_string(axis), [p] { return std::make_unique<SweepPrune>(p); }, true});
  }
  return out;
}

/// Squared distance between triangles a and b (0 when they intersect).
Scalar sqr_distance(const std::array<Vec3, 3>& a, const std::array<Vec3, 3>& b) {
  if (geometry::triangles_intersect(a[0], a[1], a[2], b[0], b[1], b[2])) return 0;
  Scalar d2 = std::numeric_limits<Scalar>::infinity();
  for (std::size_t k = 0; k < 3; ++k) {
    d2 = std::min(d2, geometry::point_triangle(a[k], b[0], b[1], b[2]).sqr_distance);
    d2 = std::min(d2, geometry::point_triangle(b[k], a[0], a[1], a[2]).sqr_distance);
    for (std::size_t j = 0; j < 3; ++j) {
      d2 = std::min(d2, geometry::segment_segment(a[k], a[(k + 1) % 3], b[j], b[(j + 1) % 3]).sqr_distance);
    }
  }
  return d2;
}

/// The pairs a broad phase must report (the file comment), by brute force: faces sharing no
/// vertex whose boxes at `in.positions`, inflated by `in.radius`, overlap, and with `!boxes`
/// of those, the ones within 2 radius (less a relative 1e-6, for the rounding), or that
/// intersect when `in.intersection_only`; with `in.owns` given, only those that own a sub-pair.
std::vector<FacePair> brute_force(const Topology& topo, const FrameInput& in, bool boxes) {
  FrameInput current = in;
  current.previous = {};
  std::vector<Box> face_box;
  face_boxes(topo, current, false, face_box);
  const auto corners = [&](Index f) {
    const Face& t = topo.face(f);
    const auto at = [&](std::size_t k) { return in.positions[static_cast<std::size_t>(t[k])]; };
    return std::array<Vec3, 3>{at(0), at(1), at(2)};
  };
  const Scalar reach = in.intersection_only ? 0 : 2 * in.radius * (1 - 1e-6);
  // Every pair of faces, by their boxes' lower x: g after f in that order is tested while its
  // lower x is not past f's upper x (a box with a NaN side meets nothing).
  std::vector<Index> by_x(static_cast<std::size_t>(topo.num_faces()));
  std::iota(by_x.begin(), by_x.end(), 0);
  const auto lo_x = [&](Index f) { return face_box[static_cast<std::size_t>(f)].lo[0]; };
  std::sort(by_x.begin(), by_x.end(), [&](Index a, Index b) { return lo_x(a) < lo_x(b) || (lo_x(a) == lo_x(b) && a < b); });
  std::vector<FacePair> out;
  for (std::size_t i = 0; i < by_x.size(); ++i) {
    for (std::size_t j = i + 1; j < by_x.size() && lo_x(by_x[j]) <= face_box[static_cast<std::size_t>(by_x[i])].hi[0]; ++j) {
      const Index f = std::min(by_x[i], by_x[j]), g = std::max(by_x[i], by_x[j]);
      if (!face_box[static_cast<std::size_t>(f)].overlaps(face_box[static_cast<std::size_t>(g)])) continue;
      if (faces_share_vertex(topo.face(f), topo.face(g))) continue;
      if (!in.owns.empty()) {
        const unsigned a = in.owns[static_cast<std::size_t>(f)], b = in.owns[static_cast<std::size_t>(g)];
        if (!((a | b) & 1u) && !(a & b & 2u)) continue;
      }
      if (!boxes) {
        const Scalar d2 = sqr_distance(corners(f), corners(g));
        if (in.intersection_only ? d2 > 0 : !(d2 < reach * reach)) continue;
      }
      out.push_back({f, g});
    }
  }
  return out;
}

/// Why `candidates` break the contract against `expected` (brute force), or nothing.
std::optional<std::string> contract_broken(const Topology& topo, std::vector<FacePair> candidates,
                                           const std::vector<FacePair>& expected) {
  for (const FacePair& p : candidates) {
    if (!(0 <= p[0] && p[0] < p[1] && p[1] < topo.num_faces())) {
      return "candidate (" + std::to_string(p[0]) + ", " + std::to_string(p[1]) + ") is not {min, max} of two faces";
    }
    if (faces_share_vertex(topo.face(p[0]), topo.face(p[1]))) {
      return "candidate (" + std::to_string(p[0]) + ", " + std::to_string(p[1]) + ") shares a vertex";
    }
  }
  std::sort(candidates.begin(), candidates.end());
  if (const auto twice = std::adjacent_find(candidates.begin(), candidates.end()); twice != candidates.end()) {
    return "candidate (" + std::to_string((*twice)[0]) + ", " + std::to_string((*twice)[1]) + ") reported twice";
  }
  for (const FacePair& p : expected) {
    if (!std::binary_search(candidates.begin(), candidates.end(), p)) {
      return "missing pair (" + std::to_string(p[0]) + ", " + std::to_string(p[1]) + ") of " +
             std::to_string(expected.size()) + " overlapping";
    }
  }
  return std::nullopt;
}

std::vector<FacePair> flatten(const CandidateBuffer& buffer) {
  std::vector<FacePair> out;
  for (const auto& chunk : buffer.chunks()) out.insert(out.end(), chunk.begin(), chunk.end());
  return out;
}

/// A default `hash` grid's candidates for one frame of `topo`, with the grid's stats.
std::vector<FacePair> hash_pairs(const Topology& topo, const FrameInput& in, DetectorStats& stats) {
  HashGrid grid{HashParams{}};
  grid.build(topo);
  grid.update(in, stats);
  CandidateBuffer buffer;
  grid.self_pairs(buffer, stats);
  return flatten(buffer);
}

/// A scene: a mesh and its frames (positions in order), with the radius to inflate by.
struct Scene {
  std::string name;
  TriMesh mesh;
  std::vector<Positions> frames;
  Scalar radius;
};

/// Frames of a mesh: at rest, jittered, jittered more, moved rigidly (all at once: the
/// caches that assume coherence must notice), and jittered again.
std::vector<Positions> seeded_frames(const TriMesh& mesh, Scalar scale, std::uint64_t seed) {
  std::vector<Positions> frames{mesh.positions()};
  frames.push_back(testing::jitter(frames.back(), 0.01 * scale, seed));
  frames.push_back(testing::jitter(frames.back(), 0.05 * scale, seed + 1));
  Positions moved = frames.back();
  for (Vec3& p : moved) p += Vec3(0.3, -0.2, 0.1) * scale;
  frames.push_back(std::move(moved));
  frames.push_back(testing::jitter(frames.back(), 0.2 * scale, seed + 2));
  return frames;
}

/// `mesh` plus one triangle `size` units across, slanted through it (issue 45: its box spans
/// far more grid cells than the mesh has faces).
TriMesh with_huge_triangle(const TriMesh& mesh, Scalar size) {
  Positions positions = mesh.positions();
  const auto faces = mesh.topology().faces();
  std::vector<Face> all(faces.begin(), faces.end());
  const Index v = static_cast<Index>(positions.size());
  positions.push_back(Vec3(-size / 2, -size / 2, -0.3));
  positions.push_back(Vec3(size / 2, -size / 3, 0.2));
  positions.push_back(Vec3(0.1, size / 2, 0.05));
  all.push_back({v, v + 1, v + 2});
  return TriMesh::create(std::move(positions), std::move(all));
}

std::vector<Scene> small_scenes() {
  std::vector<Scene> out;
  std::uint64_t seed = 11;
  for (auto& [name, mesh] : testing::small_meshes()) {
    const Scalar scale = compute_bounds(mesh.positions()).diagonal();
    out.push_back({name, mesh, seeded_frames(mesh, scale, seed++), 0.02 * scale});
  }
  const TriMesh folded = shapes::folded_cloth({.n = 12, .gap = 0.03, .wave = 0.01, .thickness = 0.05});
  out.push_back({"folded12", folded, seeded_frames(folded, 1, 21), 0.02});
  const TriMesh lattice = shapes::lattice(16, 16, 1, 1);
  const auto faces = lattice.topology().faces();
  const TriMesh crumpled = TriMesh::create(testing::crumple_lattice(lattice, 0.3, 5), {faces.begin(), faces.end()});
  out.push_back({"crumpled16", crumpled, seeded_frames(crumpled, 1, 31), 0.01});
  const TriMesh huge = with_huge_triangle(shapes::lattice(16, 16, 1, 1), 20);
  out.push_back({"lattice16+huge", huge, seeded_frames(huge, 1, 41), 0.01});
  return out;
}

/// Seeded owner bits: about half the faces own a vertex, half an edge.
std::vector<std::uint8_t> seeded_owns(Index faces, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::vector<std::uint8_t> owns(static_cast<std::size_t>(faces));
  for (std::uint8_t& o : owns) o = static_cast<std::uint8_t>(rng() & 3u);
  return owns;
}

/// Brute-force results, computed once per scene, frame and query.
std::map<std::tuple<std::string, std::size_t, bool, bool, bool>, std::vector<FacePair>>& expected_cache() {
  static std::map<std::tuple<std::string, std::size_t, bool, bool, bool>, std::vector<FacePair>> cache;
  return cache;
}

/// Runs `maker`'s broad phase over every frame of `scene` (with the previous frame as motion
/// when `motion`), checking each frame against brute force; returns the first failure.
std::optional<std::string> check_scene(const Maker& maker, const Scene& scene, int threads, bool motion,
                                       bool with_owns, bool intersection_only) {
  const Topology& topo = scene.mesh.topology();
  const std::vector<std::uint8_t> owns = seeded_owns(topo.num_faces(), 3);
  std::unique_ptr<BroadPhase> bp = maker.make();
  bp->build(topo);
  CandidateBuffer buffer;
  DetectorStats stats;
  for (std::size_t i = 0; i < scene.frames.size(); ++i) {
    FrameInput in{motion && i > 0 ? PositionsView(scene.frames[i - 1]) : PositionsView{}, scene.frames[i],
                  scene.radius, threads, intersection_only, {}};
    if (with_owns) in.owns = owns;
    bp->update(in, stats);
    buffer.clear();
    bp->self_pairs(buffer, stats);
    EXPECT_EQ(buffer.total(), flatten(buffer).size());
    const auto key = std::tuple(scene.name, i, with_owns, intersection_only, maker.boxes);
    auto found = expected_cache().find(key);
    if (found == expected_cache().end()) found = expected_cache().emplace(key, brute_force(topo, in, maker.boxes)).first;
    if (auto why = contract_broken(topo, flatten(buffer), found->second)) {
      return maker.name + " on " + scene.name + " frame " + std::to_string(i) + ", threads " +
             std::to_string(threads) + (motion ? ", with motion" : "") + (with_owns ? ", with owns" : "") +
             (intersection_only ? ", intersection only" : "") + ": " + *why;
    }
  }
  return std::nullopt;
}

TEST(BroadPhase, EveryMethodAndParameterHoldsEveryOverlappingPair) {
  const std::vector<Scene> scenes = small_scenes();
  // Every maker on every scene in every query (plain, proximity with owns, intersection only)
  // at one thread count, and one query at the other thread count with motion, in turn.
  constexpr std::array<std::pair<bool, bool>, 3> kQueries{{{false, false}, {true, false}, {false, true}}};
  std::size_t turn = 0;
  for (const Maker& maker : every_broad_phase()) {
    for (const Scene& scene : scenes) {
      for (const auto& [with_owns, intersection_only] : kQueries) {
        const auto why = check_scene(maker, scene, 1, false, with_owns, intersection_only);
        ASSERT_FALSE(why.has_value()) << *why;
      }
      const auto& [with_owns, intersection_only] = kQueries[turn++ % kQueries.size()];
      const auto why = check_scene(maker, scene, 3, true, with_owns, intersection_only);
      ASSERT_FALSE(why.has_value()) << *why;
    }
  }
}

TEST(BroadPhase, RealMeshesHoldEveryOverlappingPair) {
  std::vector<Scene> scenes;
  const TriMesh bunny = io::read_mesh(testing::data_path("ipc-toolkit-tests/bunny.ply"));
  const Scalar bunny_scale = compute_bounds(bunny.positions()).diagonal();
  scenes.push_back({"bunny", bunny, seeded_frames(bunny, 0.01 * bunny_scale, 41), 0.002 * bunny_scale});
  const TriMesh cloth0 = io::read_mesh(testing::data_path("ipc-toolkit-tests/thick-cloth/t0.ply"));
  const Positions cloth1 = io::read_mesh(testing::data_path("ipc-toolkit-tests/thick-cloth/t1.ply")).positions();
  scenes.push_back({"thick-cloth", cloth0, {cloth0.positions(), cloth1}, 1e-3 * compute_bounds(cloth1).diagonal()});
  const TriMesh arm0 = io::read_mesh(testing::data_path("sample-scalable-ccd/armadillo-rollers/frames/326.ply"));
  const Positions arm1 =
      io::read_mesh(testing::data_path("sample-scalable-ccd/armadillo-rollers/frames/327.ply")).positions();
  scenes.push_back({"armadillo", arm0, {arm0.positions(), arm1}, 1e-3 * compute_bounds(arm1).diagonal()});
  std::vector<Maker> makers;
  makers.push_back({"kdop", [] { return std::make_unique<KdopTree>(KdopParams{}); }});
  KdopParams k6;
  k6.k = 6;
  k6.arity = 8;
  k6.leaf = 7;
  k6.sweep = true;
  makers.push_back({"kdop:k=6,arity=8,leaf=7,sweep=on", [k6] { return std::make_unique<KdopTree>(k6); }});
  makers.push_back({"hash", [] { return std::make_unique<HashGrid>(HashParams{}); }, true});
  makers.push_back({"sap", [] { return std::make_unique<SweepPrune>(SapParams{}); }, true});
  for (const Maker& maker : makers) {
    for (const Scene& scene : scenes) {
      for (const int threads : {1, 2}) {
        const auto why = check_scene(maker, scene, threads, threads == 2, threads == 2, false);
        ASSERT_FALSE(why.has_value()) << *why;
      }
    }
  }
}

// Issue 45: one large triangle made `hash` enter every grid cell its box spans (bad_alloc on a
// 200 x 200 lattice with a 2,000-unit triangle). The grid's entries are bounded by the faces,
// and the pairs with the large triangle are still all there.
TEST(BroadPhase, HashCellsAreBoundedByTheFacesWhateverTheirSize) {
  for (const auto& [n, size] : {std::pair<Index, Scalar>{40, 20}, {200, 2000}}) {
    const TriMesh mesh = with_huge_triangle(shapes::lattice(n, n, 1, 1), size);
    const Topology& topo = mesh.topology();
    const FrameInput in{{}, mesh.positions(), 0.001, 2, false, {}};
    DetectorStats stats;
    const std::vector<FacePair> pairs = hash_pairs(topo, in, stats);
    EXPECT_LE(stats.get("hash_cells"), 16.0 * topo.num_faces()) << n << " x " << n << " + " << size;
    EXPECT_EQ(stats.get("hash_oversized"), 1.0);
    if (n == 40) {
      const auto why = contract_broken(topo, pairs, brute_force(topo, in, true));
      EXPECT_FALSE(why.has_value()) << *why;
    }
  }
}

// The oversized faces' pairs cost about F log(oversized) box tests plus the pairs found, not
// F x oversized (every face against every oversized face). A 100 x 100 lattice under a 20 x 20 tiling of slanted triangles,
// each spanning over 64 cells: 8.2e6 box tests for every face against each, 4.2e5 by the tree.
TEST(BroadPhase, HashOversizedFacesCostFarLessThanEveryFaceAgainstEach) {
  const TriMesh lattice = shapes::lattice(100, 100, 1, 1);
  Positions positions = lattice.positions();
  const auto lattice_faces = lattice.topology().faces();
  std::vector<Face> faces(lattice_faces.begin(), lattice_faces.end());
  constexpr int kTiles = 20;
  constexpr Scalar kTile = 1.0 / kTiles;
  for (int i = 0; i < kTiles; ++i) {
    for (int j = 0; j < kTiles; ++j) {
      const Scalar x = i * kTile, y = j * kTile;
      const Index v = static_cast<Index>(positions.size());
      positions.push_back(Vec3(x + 0.1 * kTile, y + 0.1 * kTile, -0.03));
      positions.push_back(Vec3(x + 0.9 * kTile, y + 0.1 * kTile, 0));
      positions.push_back(Vec3(x + 0.5 * kTile, y + 0.9 * kTile, 0.03));
      faces.push_back({v, v + 1, v + 2});
    }
  }
  const TriMesh mesh = TriMesh::create(std::move(positions), std::move(faces));
  const Topology& topo = mesh.topology();
  const double all_against_oversized = double(topo.num_faces()) * kTiles * kTiles;
  for (const int threads : {1, 2}) {
    const FrameInput in{{}, mesh.positions(), 0.001, threads, false, {}};
    DetectorStats stats;
    const std::vector<FacePair> pairs = hash_pairs(topo, in, stats);
    ASSERT_EQ(stats.get("hash_oversized"), kTiles * kTiles) << threads << " threads";
    const double tests = stats.get("hash_oversized_tests");
    EXPECT_GT(tests, 0) << threads << " threads";
    EXPECT_LT(tests, all_against_oversized / 8) << threads << " threads";
    const auto why = contract_broken(topo, pairs, brute_force(topo, in, true));
    EXPECT_FALSE(why.has_value()) << *why;
  }
}

// Issue 45: the kdop tree grew its patches over `face_faces`, whose size is the square of a
// vertex's valence (a fan of n faces around one vertex has n^2 pairs). Building and querying
// the tree on a fan twice as large takes at most about twice the topology's memory.
TEST(BroadPhase, KdopTreeOnAFanNeedsNoQuadraticAdjacency) {
  const auto fan = [](Index n) {
    Positions positions{Vec3::Zero()};
    std::vector<Face> faces;
    for (Index i = 0; i < n; ++i) {
      const Scalar a = 2 * 3.14159265358979 * static_cast<Scalar>(i) / static_cast<Scalar>(n);
      positions.push_back(Vec3(std::cos(a), std::sin(a), 0.01 * static_cast<Scalar>(i % 2)));
      faces.push_back({0, 1 + i, 1 + (i + 1) % n});
    }
    return TriMesh::create(std::move(positions), std::move(faces));
  };
  std::vector<double> bytes;
  for (const Index n : {2000, 4000}) {
    const TriMesh mesh = fan(n);
    const Topology& topo = mesh.topology();
    KdopTree tree{KdopParams{}};
    tree.build(topo);
    DetectorStats stats;
    tree.update(FrameInput{{}, mesh.positions(), 1e-4, 1, false, {}}, stats);
    CandidateBuffer buffer;
    tree.self_pairs(buffer, stats);
    bytes.push_back(static_cast<double>(topo.memory_bytes()));
  }
  EXPECT_LE(bytes[1], 2.2 * bytes[0]) << bytes[0] << " then " << bytes[1] << " bytes";
}

// The check itself can fail: a broad phase's output with one required pair dropped, or one
// pair reported twice, or a pair of faces that share a vertex, is caught.
TEST(BroadPhase, TheBruteForceCheckCatchesADroppedPair) {
  const Scene scene = small_scenes().back();
  const Topology& topo = scene.mesh.topology();
  const FrameInput in{{}, scene.frames[0], scene.radius, 1, false, {}};
  const std::vector<FacePair> expected = brute_force(topo, in, false);
  ASSERT_GT(expected.size(), 10u);
  KdopTree tree{KdopParams{}};
  tree.build(topo);
  DetectorStats stats;
  tree.update(in, stats);
  CandidateBuffer buffer;
  tree.self_pairs(buffer, stats);
  const std::vector<FacePair> candidates = flatten(buffer);
  ASSERT_FALSE(contract_broken(topo, candidates, expected).has_value());
  for (const std::size_t drop : {std::size_t{0}, expected.size() / 2, expected.size() - 1}) {
    std::vector<FacePair> fewer;
    std::copy_if(candidates.begin(), candidates.end(), std::back_inserter(fewer),
                 [&](const FacePair& p) { return p != expected[drop]; });
    ASSERT_EQ(fewer.size() + 1, candidates.size());
    const auto why = contract_broken(topo, fewer, expected);
    ASSERT_TRUE(why.has_value());
    EXPECT_NE(why->find("missing pair"), std::string::npos) << *why;
  }
  std::vector<FacePair> twice = candidates;
  twice.push_back(candidates.front());
  EXPECT_TRUE(contract_broken(topo, twice, expected).has_value());
  std::vector<FacePair> adjacent = candidates;
  adjacent.push_back({0, 1});  // the lattice's first two faces share an edge
  ASSERT_TRUE(faces_share_vertex(topo.face(0), topo.face(1)));
  EXPECT_TRUE(contract_broken(topo, adjacent, expected).has_value());
}

}  // namespace
}  // namespace crumple
