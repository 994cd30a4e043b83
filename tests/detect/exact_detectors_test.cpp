// The exact detectors (kdop, hash, sap) return exactly the `naive` contact set: same pairs,
// bit-identical distances (checked to 1e-12 relative, and through a hash of the 17-digit text
// for the cached real-mesh references), on the mesh group, seeded random deformations and
// motions, adversarial scenes, the small ipc-toolkit meshes, and the five real scenes
// (against tests/data/reference/real_meshes.txt; regenerate with bench/exact_bench, see its
// header). Metamorphic: the result does not depend on k, arity, leaf size, hash cell or table
// size, sweep axis or thread count.
#include <crumple/detect/exact_detector.hpp>
#include <crumple/detect/detector.hpp>
#include <crumple/detect/broad_phase/kdop_tree.hpp>
#include <crumple/io/mesh_io.hpp>
#include <support/meshes.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <functional>
#include <limits>
#include <map>
#include <ostream>
#include <numbers>
#include <random>
#include <set>
#include <sstream>
#include <string>
#include <vector>

namespace crumple {
namespace {

#if defined(__SANITIZE_ADDRESS__)
constexpr bool kSanitized = true;
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
constexpr bool kSanitized = true;
#else
constexpr bool kSanitized = false;
#endif
#else
constexpr bool kSanitized = false;
#endif

/// Every exact detector with default parameters, then variations of every parameter.
const std::vector<std::string>& default_specs() {
  static const std::vector<std::string> specs{"kdop", "hash", "sap"};
  return specs;
}
const std::vector<std::string>& all_specs() {
  static const std::vector<std::string> specs{
      "kdop",
      "kdop:k=6,arity=2,leaf=1",
      "kdop:k=14,arity=8,leaf=2",
      "kdop:k=26,arity=2,leaf=16",
      "kdop:k=18,arity=8,leaf=64,rebuild=1",
      "kdop:sweep=on",
      "hash",
      "hash:cell=0.5,table=97",
      "hash:cell=1,table=1009",
      "hash:cell=2,table=100003",
      "sap",
      "sap:axis=x",
      "sap:axis=z",
  };
  return specs;
}

std::unique_ptr<Detector> make(const std::string& spec, Scalar h, ContactKinds kinds = {}, int threads = 0) {
  return make_detector(MethodSpec::parse(spec), {.thickness = h, .kinds = kinds, .threads = threads});
}

ContactSet run(const std::string& spec, const TriMesh& mesh, PositionsView previous, PositionsView x,
               Scalar h, ContactKinds kinds = {}, int threads = 0) {
  auto d = make(spec, h, kinds, threads);
  d->set_topology(mesh.topology_ptr());
  ContactSet out;
  d->update(previous, x, out);
  return out;
}


/// `got`, found at positions and thickness 2^k times those of `want`: the same contacts, in the
/// same order, with the same barycentric coordinates, normals and edge parameters, the
/// distances 2^k times `want`'s (rounded once where they leave the normal range).
void expect_scaled(const ContactSet& want, const ContactSet& got, int k, const std::string& what) {
  SCOPED_TRACE(what);
  ASSERT_EQ(want.vf.size(), got.vf.size()) << "VF count";
  ASSERT_EQ(want.ee.size(), got.ee.size()) << "EE count";
  ASSERT_EQ(want.tt.size(), got.tt.size()) << "TT count";
  for (std::size_t i = 0; i < want.vf.size(); ++i) {
    ASSERT_EQ(want.vf[i].vertex, got.vf[i].vertex) << "VF " << i;
    ASSERT_EQ(want.vf[i].face, got.vf[i].face) << "VF " << i;
    ASSERT_EQ(std::scalbn(want.vf[i].distance, k), got.vf[i].distance) << "VF " << i;
    ASSERT_EQ(want.vf[i].barycentric, got.vf[i].barycentric) << "VF " << i;
    ASSERT_EQ(want.vf[i].normal, got.vf[i].normal) << "VF " << i;
  }
  for (std::size_t i = 0; i < want.ee.size(); ++i) {
    ASSERT_EQ(want.ee[i].a, got.ee[i].a) << "EE " << i;
    ASSERT_EQ(want.ee[i].b, got.ee[i].b) << "EE " << i;
    ASSERT_EQ(want.ee[i].edge0, got.ee[i].edge0) << "EE " << i;
    ASSERT_EQ(want.ee[i].edge1, got.ee[i].edge1) << "EE " << i;
    ASSERT_EQ(std::scalbn(want.ee[i].distance, k), got.ee[i].distance) << "EE " << i;
    ASSERT_EQ(want.ee[i].s, got.ee[i].s) << "EE " << i;
    ASSERT_EQ(want.ee[i].t, got.ee[i].t) << "EE " << i;
    ASSERT_EQ(want.ee[i].normal, got.ee[i].normal) << "EE " << i;
  }
  for (std::size_t i = 0; i < want.tt.size(); ++i) {
    ASSERT_EQ(want.tt[i].face0, got.tt[i].face0) << "TT " << i;
    ASSERT_EQ(want.tt[i].face1, got.tt[i].face1) << "TT " << i;
  }
}

/// Same pairs in the same (canonical) order and every field bit-identical (the design's claim;
/// the bar is distances equal to 1e-12 relative).
void expect_same(const ContactSet& want, const ContactSet& got, const std::string& what) {
  SCOPED_TRACE(what);
  if (want.vf.size() != got.vf.size()) {  // name the pairs that differ
    std::set<std::pair<Index, Index>> a, b;
    for (const auto& c : want.vf) a.insert({c.vertex, c.face});
    for (const auto& c : got.vf) b.insert({c.vertex, c.face});
    for (const auto& [v, f] : a) {
      if (!b.count({v, f})) ADD_FAILURE() << "missed VF " << v << " " << f;
    }
    for (const auto& [v, f] : b) {
      if (!a.count({v, f})) ADD_FAILURE() << "false VF " << v << " " << f;
    }
  }
  expect_scaled(want, got, 0, "");
}

/// Runs every spec in `specs` on a sequence of frames (each with the previous one as motion,
/// the first without) through one detector per spec, comparing with naive every
/// `check_every`-th frame and the last (every detector still sees every frame, so coherence is
/// exercised whole). Returns the total number of reference contacts over the compared frames.
std::size_t expect_sequence_exact(const TriMesh& mesh, const std::vector<Positions>& frames, Scalar h,
                                  const std::vector<std::string>& specs, ContactKinds kinds = ContactKinds::parse("vf,ee,tt"),
                                  const std::vector<int>& thread_counts = {0}, std::size_t check_every = 1) {
  const auto checked = [&](std::size_t i) { return i % check_every == 0 || i + 1 == frames.size(); };
  std::vector<ContactSet> want(frames.size());
  auto naive = make("naive", h, kinds);
  naive->set_topology(mesh.topology_ptr());
  std::size_t total = 0;
  for (std::size_t i = 0; i < frames.size(); ++i) {
    if (!checked(i)) continue;
    naive->update(frames[i], want[i]);
    total += want[i].size();
  }
  for (int threads : thread_counts) {
  for (const std::string& spec : specs) {
    auto d = make(spec, h, kinds, threads);
    d->set_topology(mesh.topology_ptr());
    for (std::size_t i = 0; i < frames.size(); ++i) {
      ContactSet got;
      d->update(i == 0 ? PositionsView{} : PositionsView(frames[i - 1]), frames[i], got);
      if (!checked(i)) continue;
      expect_same(want[i], got, spec + " frame " + std::to_string(i) + " threads " + std::to_string(threads));
      if (::testing::Test::HasFatalFailure()) return total;
    }
  }
  }
  return total;
}

/// The vertex-face contacts of `set` between a vertex and a face next to one of its own faces
/// (orphan pairs).
std::size_t orphan_vertex_face_contacts(const Topology& topo, const ContactSet& set) {
  std::size_t n = 0;
  for (const auto& c : set.vf) {
    bool orphan = false;
    for (Index f : topo.vertex_faces()[c.vertex]) {
      for (Index w : topo.face(f)) orphan |= topo.face_has_vertex(c.face, w);
    }
    n += orphan ? 1u : 0u;
  }
  return n;
}

/// Appends the faces of `topo` to `faces`, their vertex ids shifted by `offset` (one more copy
/// of a piece in a mesh made of several).
void append_faces(std::vector<Face>& faces, const Topology& topo, Index offset) {
  for (Face f : topo.faces()) faces.push_back({f[0] + offset, f[1] + offset, f[2] + offset});
}

std::vector<Positions> blend(PositionsView a, PositionsView b, int steps) {
  std::vector<Positions> out;
  for (int s = 0; s <= steps; ++s) {
    const double t = static_cast<double>(s) / steps;
    Positions x(a.size());
    for (std::size_t i = 0; i < a.size(); ++i) x[i] = (1 - t) * a[i] + t * b[i];
    out.push_back(std::move(x));
  }
  return out;
}

// ---- synthetic meshes ----------------------------------------------------------------------

TEST(ExactDetectors, MeshGroupWithRandomMotionAllSpecs) {
  for (const auto& [name, mesh] : testing::small_meshes()) {
    for (std::uint64_t seed : {1u, 2u, 3u}) {
      SCOPED_TRACE(name + " seed " + std::to_string(seed));
      const EdgeLengthStats e = edge_length_stats(mesh.topology(), mesh.positions());
      const std::vector<Positions> frames{testing::jitter(mesh.positions(), 0.3 * e.mean, seed),
                                          testing::jitter(mesh.positions(), 0.3 * e.mean, seed + 100),
                                          testing::jitter(mesh.positions(), 0.6 * e.mean, seed + 200)};
      for (double rel : {0.1, 0.5}) {
        expect_sequence_exact(mesh, frames, rel * e.mean, all_specs());
        if (HasFatalFailure()) return;
      }
    }
  }
}

TEST(ExactDetectors, CrumplingLatticeSequenceAllSpecsAndThreads) {
  // A flat lattice crumpling over 6 frames (coherent motion, growing contact count, the k-DOP
  // quality metric degrading: rebuilds happen), for several seeds.
  const TriMesh lattice = shapes::lattice(24, 24);
  std::size_t total = 0;
  for (std::uint64_t seed = 10; seed < 12; ++seed) {
    SCOPED_TRACE("seed " + std::to_string(seed));
    const Positions crumpled = testing::crumple_lattice(lattice, 0.15, seed);
    const auto frames = blend(lattice.positions(), crumpled, 3);
    total += expect_sequence_exact(lattice, frames, 0.03, seed == 10 ? all_specs() : default_specs(),
                                   ContactKinds::parse("vf,ee,tt"), {1, 2, 3});
    if (HasFatalFailure()) return;
  }
  EXPECT_GT(total, 1000u) << "the crumpling lattices should produce contacts";
}

// The orphan blocks are skipped while their vertices have not moved, relative to one another,
// by enough to close a block's margin since the last refresh (temporal coherence). A lattice is
// carried rigidly (blocks asleep), then folded shut along a grid line in small steps: the orphan
// pairs across the crease come within h one after another and must be found on the frame they
// do, by every detector and thread count.
TEST(ExactDetectors, OrphanBlocksSleepOnlyWhileTheyCannotTouch) {
  const TriMesh lattice = shapes::lattice(16, 16);
  const Positions& flat = lattice.positions();
  std::vector<Positions> frames;
  for (int k = 0; k < 6; ++k) {  // rigid: rotation about z and translation
    const double a = 0.002 * k;
    Positions x(flat.size());
    for (std::size_t i = 0; i < x.size(); ++i) {
      const Vec3& p = flat[i];
      x[i] = Vec3(std::cos(a) * p.x() - std::sin(a) * p.y(), std::sin(a) * p.x() + std::cos(a) * p.y(), p.z()) +
             k * Vec3(5, -3, 2);
    }
    frames.push_back(std::move(x));
  }
  const Vec3 shift = 5 * Vec3(5, -3, 2);
  for (int k = 1; k <= 36; ++k) {  // folded about x = 0.5 (lattice frame), up to 175 degrees
    const double phi = std::numbers::pi * 175.0 / 180.0 * k / 36;
    Positions x(flat.size());
    for (std::size_t i = 0; i < x.size(); ++i) {
      const Vec3& p = flat[i];
      const Vec3 q = p.x() > 0.5 ? Vec3(0.5 + (p.x() - 0.5) * std::cos(phi), p.y(), (p.x() - 0.5) * std::sin(phi)) : p;
      const double a = 0.01;
      x[i] = Vec3(std::cos(a) * q.x() - std::sin(a) * q.y(), std::sin(a) * q.x() + std::cos(a) * q.y(), q.z()) + shift;
    }
    frames.push_back(std::move(x));
  }
  const Scalar h = 0.02;
  const std::size_t n = expect_sequence_exact(lattice, frames, h, default_specs(), ContactKinds::parse("vf,ee,tt"), {1, 2});
  if (HasFatalFailure()) return;
  EXPECT_GT(n, 1000u);

  // The skipping did happen, and contacts between orphans (a vertex against a face next to one of
  // its own faces) were found while it did.
  auto d = make("kdop", h, ContactKinds::parse("vf,ee"), 1);
  d->set_topology(lattice.topology_ptr());
  const Topology& topo = lattice.topology();
  std::size_t asleep_frames = 0, orphan_contacts = 0;
  for (std::size_t i = 0; i < frames.size(); ++i) {
    ContactSet got;
    d->update(frames[i], got);
    if (d->stats().get("orphan_blocks_tested") < d->stats().get("orphan_blocks")) ++asleep_frames;
    orphan_contacts += orphan_vertex_face_contacts(topo, got);
  }
  EXPECT_GE(asleep_frames, 5u) << "the blocks should sleep while the lattice moves rigidly";
  EXPECT_GT(orphan_contacts, 0u) << "the fold should bring orphan pairs within h";
}

// The wake check's sample decides a frame (more than 1024 blocks, a sample of every 16th): a
// fine lattice whose blocks all hold orphan pairs within h (its right-angle corners are 0.71
// edge lengths from the hypotenuse's other face, h is 0.8), 85% of the blocks, always awake; a
// coarse one far off whose blocks sleep on frame 1 (no motion, the sample's awake share below
// 7/8: every block checked). On frame 2 the coarse lattice's right part folds 179.5 degrees
// onto its left part, waking its blocks (less than a quarter of all: not stale): the sample is
// then nearly all awake, the frame tests every block, and the folded pairs of adjacent faces
// (0.0087 apart) are found. A block left with its frame-1 flag would sleep through them. The
// lattices are apart, so the reference is `naive` on the coarse lattice alone (the fine one
// alone would take minutes under the sanitizers), and the fine lattice, which does not move,
// keeps the contacts of frame 0 (a refresh: every block tested).
TEST(ExactDetectors, OrphanWakeSampleWakesEveryBlock) {
  const TriMesh fine = shapes::lattice(64, 64);
  const TriMesh coarse = shapes::lattice(27, 27, 27, 27);
  const Scalar h = 0.8 / 64;
  const Vec3 off(100, 0, 0);
  const auto folded = [&](double fold) {  // the coarse lattice, folded about x = 13
    Positions x;
    for (const Vec3& p : coarse.positions()) {
      const double u = p.x() - 13;
      x.push_back(off + (u > 0 ? Vec3(13 + u * std::cos(fold), p.y(), u * std::sin(fold)) : p));
    }
    return x;
  };
  const auto frame = [&](double fold) {
    Positions x = fine.positions();
    for (const Vec3& p : folded(fold)) x.push_back(p);
    return x;
  };
  std::vector<Face> faces(fine.topology().faces().begin(), fine.topology().faces().end());
  const Index base = static_cast<Index>(fine.positions().size());
  const Index fine_faces = fine.topology().num_faces(), fine_edges = fine.topology().num_edges();
  append_faces(faces, coarse.topology(), base);
  const TriMesh mesh = TriMesh::create(frame(0), faces);
  const double fold = std::numbers::pi * 179.5 / 180;
  const std::vector<Positions> frames{frame(0), frame(0), frame(fold)};

  const TriMesh alone = TriMesh::create(folded(0), std::vector<Face>(coarse.topology().faces().begin(),
                                                                     coarse.topology().faces().end()));
  const ContactSet want = run("naive", alone, {}, folded(fold), h, ContactKinds::parse("vf,ee"));
  ASSERT_GT(orphan_vertex_face_contacts(alone.topology(), want), 0u) << "the fold should bring orphan pairs within h";
  // A frame's contacts on the coarse lattice (renumbered as `alone`), or on the fine one.
  const auto part = [&](const ContactSet& set, bool on_coarse) {
    ContactSet out;
    for (VertexFaceContact c : set.vf) {
      if ((c.vertex >= base) != on_coarse) continue;
      if (on_coarse) {
        c.vertex -= base;
        c.face -= fine_faces;
      }
      out.vf.push_back(c);
    }
    for (EdgeEdgeContact c : set.ee) {
      if ((c.a[0] >= base) != on_coarse) continue;
      if (on_coarse) {
        c.edge0 -= fine_edges;
        c.edge1 -= fine_edges;
        c.a = {c.a[0] - base, c.a[1] - base};
        c.b = {c.b[0] - base, c.b[1] - base};
      }
      out.ee.push_back(c);
    }
    return out;
  };
  for (int threads : {1, 2}) {
    SCOPED_TRACE("threads " + std::to_string(threads));
    auto d = make("kdop", h, ContactKinds::parse("vf,ee"), threads);
    d->set_topology(mesh.topology_ptr());
    ContactSet first, got;
    d->update(frames[0], first);
    ASSERT_GT(d->stats().get("orphan_blocks"), 1024);
    d->update(frames[0], frames[1], got);
    EXPECT_EQ(d->stats().get("orphan_sampled"), 0) << "frame 1: the sample should not decide";
    EXPECT_LT(d->stats().get("orphan_blocks_tested"), d->stats().get("orphan_blocks")) << "the coarse blocks sleep";
    d->update(frames[1], frames[2], got);
    EXPECT_EQ(d->stats().get("orphan_sampled"), 1) << "frame 2: nearly all of the sample is awake";
    EXPECT_EQ(d->stats().get("orphan_refresh"), 0) << "the frame should not be stale";
    EXPECT_EQ(d->stats().get("orphan_blocks_tested"), d->stats().get("orphan_blocks"));
    expect_same(want, part(got, true), "coarse lattice, frame 2");
    expect_same(part(first, false), part(got, false), "fine lattice, frame 2 against frame 0");
    EXPECT_GT(part(got, false).size(), 0u);
  }
}

// Two triangles sharing only vertex w: every sub-pair between them is an orphan, in one block
// of each kind. A static lattice far off adds blocks that sleep, so that the frame does not
// count as stale (which would test every block); it is coarse, so that its sub-pairs, which
// share blocks with the triangles', are far apart. On frame 0 (a refresh) the nearest orphan pair
// of the triangles is 4h apart; on the next frame, b1 and b2 move 3.5h towards A (w, a1, a2
// stay), down to 0.5h. The vertex-face block's bound is then beaten by twice the motion and it
// must be tested: a bound overestimated even threefold would let it sleep through the contacts.
// One scene per way a refresh bounds a pair: the pair's box gap (b1 above a level A), its plane
// distance (the same, tilted: b1 is inside A's box) and the kernel's distance (b1 level with A,
// beside its edge w-a1, inside its box). A smaller step (4h -> 3h) leaves every block provably
// apart, and asleep.
TEST(ExactDetectors, OrphanBoundsHoldAtEveryKindOfRejection) {
  const Scalar h = 0.01;
  const Vec3 beside = Vec3(1, -1, 0).normalized();
  const Eigen::Matrix3d tilt = Eigen::AngleAxisd(std::numbers::pi / 6, Vec3::UnitX()).toRotationMatrix();
  struct Scene {
    std::string name;
    Positions base;  // w, a1, a2, b1, b2 with b1 and b2 at their nearest to A
    Vec3 away;       // the direction in which b1 and b2 are moved away from there
    Eigen::Matrix3d frame;
  };
  const std::vector<Scene> scenes{
      {"box gap", {Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0), Vec3(0.3, 0.3, 0), Vec3(0.5, 0.2, 0)}, Vec3::UnitZ(),
       Eigen::Matrix3d::Identity()},
      {"plane distance", {Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0), Vec3(0.3, 0.3, 0), Vec3(0.5, 0.2, 0)},
       Vec3::UnitZ(), tilt},
      {"kernel distance", {Vec3(0, 0, 0), Vec3(1, 1, 0), Vec3(-1, 1, 0), Vec3(0.5, 0.5, 0), Vec3(1, -0.5, 0)}, beside,
       Eigen::Matrix3d::Identity()},
  };
  const TriMesh far = shapes::lattice(12, 12, 100, 100);
  for (const Scene& scene : scenes) {
    SCOPED_TRACE(scene.name);
    const auto at = [&](Scalar d) {
      Positions x = scene.base;
      for (std::size_t i : {3u, 4u}) x[i] += d * scene.away;
      for (Vec3& p : x) p = scene.frame * p;
      for (const Vec3& p : far.positions()) x.push_back(p + Vec3(200, 0, 0));
      return x;
    };
    std::vector<Face> faces{{0, 1, 2}, {0, 3, 4}};
    append_faces(faces, far.topology(), 5);
    const TriMesh mesh = TriMesh::create(at(0), faces);
    const std::vector<Positions> closing{at(4 * h), at(0.5 * h)};
    const std::size_t n = expect_sequence_exact(mesh, closing, h, default_specs(), ContactKinds::parse("vf,ee"), {1, 2});
    if (HasFatalFailure()) return;
    EXPECT_GT(n, 0u) << "b1 should touch A on the second frame";

    auto d = make("kdop", h, ContactKinds::parse("vf,ee"), 1);
    d->set_topology(mesh.topology_ptr());
    ContactSet got;
    d->update(at(4 * h), got);
    ASSERT_GT(d->stats().get("orphan_blocks"), 8);
    d->update(at(4 * h), at(3 * h), got);
    EXPECT_TRUE(got.empty());
    EXPECT_EQ(d->stats().get("orphan_blocks_tested"), 0) << "4h apart and 2h of closing: every block can sleep";
  }
}

// A NaN vertex must not put its orphan blocks to sleep: the wake check measures the motion
// relative to a block's first vertex, its smallest, here the shared vertex w of two triangles
// A = (w, a1, a2) and B = (w, b1, b2). On frame 0 (a refresh) B's far edge b1-b2 crosses 4h
// above A's far edge a1-a2; on frame 1 w is NaN and b1, b2 have come down to 0.5h. The
// sub-pairs with w have NaN distances and no contact, but a1-a2 against b1-b2 is one, of
// finite vertices, and its block must be tested. (A motion that skipped the NaN, as a maximum
// by `<` does, counted the block unmoved, and it slept through the contact.) The static
// lattice far off keeps the frame from counting as stale, as above.
TEST(ExactDetectors, OrphanBlocksWakeWhenTheirFirstVertexIsNaN) {
  const Scalar h = 0.01;
  const TriMesh far = shapes::lattice(12, 12, 100, 100);
  const auto at = [&](Scalar z, Scalar w) {
    Positions x{Vec3(w, w, w), Vec3(1, 0, 0), Vec3(0, 1, 0), Vec3(0.8, 0.6, z), Vec3(0.3, 0.4, z)};
    for (const Vec3& p : far.positions()) x.push_back(p + Vec3(200, 0, 0));
    return x;
  };
  std::vector<Face> faces{{0, 1, 2}, {0, 3, 4}};
  append_faces(faces, far.topology(), 5);
  const TriMesh mesh = TriMesh::create(at(4 * h, 0), faces);
  const std::vector<Positions> frames{at(4 * h, 0), at(0.5 * h, std::nan(""))};
  const ContactSet want = run("naive", mesh, {}, frames[1], h, ContactKinds::parse("vf,ee"));
  ASSERT_EQ(want.ee.size(), 1u);
  EXPECT_EQ(want.ee[0].a, (Edge{1, 2}));
  EXPECT_EQ(want.ee[0].b, (Edge{3, 4}));
  expect_sequence_exact(mesh, frames, h, default_specs(), ContactKinds::parse("vf,ee"), {1, 2});
}

// A face with a NaN corner keeps the contacts of its finite side: two triangles apart, the first
// with its first corner NaN, whose far edge crosses 0.5h above two sides of the second; and the
// same with every corner of the first NaN (no contact). Its box (for sap and hash) once started
// at the NaN corner and stayed NaN, meeting nothing (sap) or refused as too large for the cells
// (hash).
TEST(ExactDetectors, FaceWithANaNCornerKeepsItsFiniteSide) {
  // At unit scale, and far from it (hash's cells come from the mean edge length: a NaN one made
  // them size 1, too small for this scale).
  for (const Scalar scale : {1.0, 1e7}) {
    SCOPED_TRACE("scale " + std::to_string(scale));
    const Scalar h = 0.01 * scale, nan = std::nan("");
    Positions x{Vec3(nan, nan, nan), Vec3(1, 0, 0.005), Vec3(0, 1, 0.005),
                Vec3(0.2, 0.2, 0),   Vec3(0.9, 0.8, 0), Vec3(0.1, 0.5, 0)};
    for (Vec3& p : x) p *= scale;
    Positions rest = x;  // a mesh is created from finite positions
    rest[0] = Vec3(0, 0, 0.005 * scale);
    const TriMesh mesh = TriMesh::create(rest, {{0, 1, 2}, {3, 4, 5}});
    const ContactSet want = run("naive", mesh, {}, x, h, ContactKinds::parse("vf,ee"));
    ASSERT_EQ(want.ee.size(), 2u);  // a1-a2 crosses two sides of the second triangle
    EXPECT_EQ(want.ee[0].a, (Edge{1, 2}));
    EXPECT_EQ(want.ee[1].a, (Edge{1, 2}));
    expect_sequence_exact(mesh, {x}, h, all_specs(), ContactKinds::parse("vf,ee,tt"), {1, 2});
    if (HasFatalFailure()) return;
    Positions all_nan = x;
    for (std::size_t i = 0; i < 3; ++i) all_nan[i] = Vec3(nan, nan, nan);
    EXPECT_EQ(run("naive", mesh, {}, all_nan, h, ContactKinds::parse("vf,ee,tt")).size(), 0u);
    expect_sequence_exact(mesh, {all_nan}, h, all_specs(), ContactKinds::parse("vf,ee,tt"), {1, 2});
  }
}

// Temporal coherence of the k-DOP traversal (`coherence=on`, the default): units whose
// vertices moved by the same vector since the refresh frame reuse its candidates. Two stacks of
// 6x6 lattices 0.6h apart (contacts inside each stack on every frame): stack A carried rigidly
// down onto stack B (its units reused, the pairs across the stacks traversed as they close in);
// in B, one lattice slides sideways by 0.3h a frame (its units beyond the slack, traversed) and
// one creeps down from 1.035h above the layer below by 0.01h a frame, within the slack, so that
// its contacts appear on frame 4 from candidates recorded on frame 0 at 1.035h: the refresh
// frame's extra inflation is what keeps them; one drops from 1.45h by 0.1h a frame (beyond the
// slack from the first frame: a spread underestimated tenfold would reuse its units, and miss
// its contacts from frame 5). Checked against naive on every frame; the units are the same
// whatever the thread count. (`rebuild=1` rebuilds the tree on reuse frames, which must record
// afresh.)
TEST(ExactDetectors, KdopCoherenceReusesOnlyWhatCannotHaveMoved) {
  const Scalar h = 0.02;
  const TriMesh piece = shapes::lattice(6, 6);
  std::vector<Vec3> origin;  // per lattice: its corner at frame 0
  for (int stack = 0; stack < 2; ++stack) {
    for (int col = 0; col < 4; ++col) {
      for (int layer = 0; layer < 4; ++layer) {
        const double z = layer * 0.6 * h + (stack == 0 ? 11.8 * h : 0);  // A's bottom 10h above B's top
        origin.emplace_back(1.2 * (col % 2) + 0.3 * stack, 1.2 * (col / 2), z);
      }
    }
  }
  // Top layers of three columns of B.
  const std::size_t slider = 16 + 3, creeper = 16 + 4 + 3, dropper = 16 + 12 + 3;
  origin[creeper].z() = 2 * 0.6 * h + 1.035 * h;
  origin[dropper].z() = 2 * 0.6 * h + 1.45 * h;
  const auto frame = [&](int k) {
    Positions x;
    for (std::size_t l = 0; l < origin.size(); ++l) {
      Vec3 o = origin[l];
      if (l < 16) o.z() -= k * h;
      if (l == slider) o.y() += 0.3 * h * k;
      if (l == creeper) o.z() -= 0.01 * h * k;
      if (l == dropper) o.z() -= 0.1 * h * k;
      for (const Vec3& p : piece.positions()) x.push_back(p + o);
    }
    return x;
  };
  std::vector<Face> faces;
  const auto nv = static_cast<Index>(piece.positions().size());
  for (std::size_t l = 0; l < origin.size(); ++l) append_faces(faces, piece.topology(), static_cast<Index>(l) * nv);
  const TriMesh mesh = TriMesh::create(frame(0), faces);
  std::vector<Positions> frames;
  for (int k = 0; k <= 12; ++k) frames.push_back(frame(k));
  const std::size_t n = expect_sequence_exact(
      mesh, frames, h,
      {"kdop", "kdop:coherence=off", "kdop:arity=2,leaf=8", "kdop:k=6,arity=8,leaf=64", "kdop:rebuild=1,leaf=16"},
      ContactKinds::parse("vf,ee"), {1, 3}, kSanitized ? 4 : 1);  // naive on 13 frames: minutes under ASan
  if (HasFatalFailure()) return;
  EXPECT_GT(n, 1000u);

  // The reuse happened while contacts appeared: the creeper's on frame 4, across the stacks.
  auto d = make("kdop", h, ContactKinds::parse("vf,ee"), 1);
  auto d3 = make("kdop", h, ContactKinds::parse("vf,ee"), 3);
  d->set_topology(mesh.topology_ptr());
  d3->set_topology(mesh.topology_ptr());
  const auto lattice_of = [&](Index v) { return static_cast<std::size_t>(v / nv); };
  std::size_t reuse_frames = 0, reused = 0, traversed = 0, creeper_from = 0, across = 0;
  for (std::size_t i = 0; i < frames.size(); ++i) {
    ContactSet got;
    d->update(i == 0 ? PositionsView{} : PositionsView(frames[i - 1]), frames[i], got);
    d3->update(i == 0 ? PositionsView{} : PositionsView(frames[i - 1]), frames[i], got);
    for (const char* key : {"coherence", "units_reused", "units_traversed"}) {
      EXPECT_EQ(d->stats().get(key), d3->stats().get(key)) << key << ", frame " << i;
    }
    if (d->stats().get("coherence") != 2) continue;
    ++reuse_frames;
    reused += static_cast<std::size_t>(d->stats().get("units_reused"));
    traversed += static_cast<std::size_t>(d->stats().get("units_traversed"));
    for (const auto& c : got.vf) {
      const std::size_t a = lattice_of(c.vertex), b = lattice_of(mesh.topology().face(c.face)[0]);
      if ((a == creeper || b == creeper) && creeper_from == 0) creeper_from = i;
      across += (a < 16) != (b < 16) ? 1u : 0u;
    }
  }
  EXPECT_GE(reuse_frames, 8u);
  EXPECT_GT(reused, traversed) << "most units moved rigidly";
  EXPECT_GT(traversed, 0u) << "the stacks closing in, and the slider, are traversed";
  EXPECT_EQ(creeper_from, 4u) << "the creeper reaches h on frame 4";
  EXPECT_GT(across, 0u) << "the stacks meet on reuse frames";
}

// A frame with a non-finite coordinate is traversed, never served from the recorded units, and
// the next finite frame records afresh: the displacement boxes that decide a reuse skip NaN (as
// `Box::grow` does), so they could not be trusted to cover it. A stack of four lattices 0.6h
// apart, carried down rigidly by 0.01h a frame (every unit reusable), with one vertex NaN on
// frame 4; exact on every frame, and the coherence mode per frame is record, reuse x3, off
// (NaN), record, reuse.
TEST(ExactDetectors, KdopCoherenceTraversesAFrameWithANaN) {
  const Scalar h = 0.02;
  const TriMesh piece = shapes::lattice(6, 6);
  const auto nv = static_cast<Index>(piece.positions().size());
  std::vector<Face> faces;
  for (Index layer = 0; layer < 4; ++layer) append_faces(faces, piece.topology(), layer * nv);
  const auto frame = [&](int k) {
    Positions x;
    for (int layer = 0; layer < 4; ++layer) {
      for (const Vec3& p : piece.positions()) x.push_back(p + Vec3(0, 0, layer * 0.6 * h - 0.01 * h * k));
    }
    if (k == 4) x[7] = Vec3(std::nan(""), 0, 0);
    return x;
  };
  const TriMesh mesh = TriMesh::create(frame(0), faces);
  std::vector<Positions> frames;
  for (int k = 0; k <= 6; ++k) frames.push_back(frame(k));
  EXPECT_GT(expect_sequence_exact(mesh, frames, h, {"kdop", "kdop:arity=2,leaf=8"}, ContactKinds::parse("vf,ee"), {1, 2}),
            100u);
  auto d = make("kdop:leaf=8", h, ContactKinds::parse("vf,ee"), 1);
  d->set_topology(mesh.topology_ptr());
  std::vector<double> modes;
  for (std::size_t i = 0; i < frames.size(); ++i) {
    ContactSet got;
    d->update(i == 0 ? PositionsView{} : PositionsView(frames[i - 1]), frames[i], got);
    modes.push_back(d->stats().get("coherence"));
  }
  EXPECT_EQ(modes, (std::vector<double>{1, 2, 2, 2, 0, 1, 2}));
}

TEST(ExactDetectors, KdopRebuildsWhenQualityDegrades) {
  const TriMesh lattice = shapes::lattice(24, 24);
  const auto frames = blend(lattice.positions(), testing::crumple_lattice(lattice, 0.3, 5), 4);
  auto d = make("kdop:rebuild=1.05", 0.03);
  d->set_topology(lattice.topology_ptr());
  ContactSet out;
  double rebuilds = 0;
  for (std::size_t i = 0; i < frames.size(); ++i) {
    d->update(i == 0 ? PositionsView{} : PositionsView(frames[i - 1]), frames[i], out);
    if (i > 0) rebuilds += d->stats().get("rebuilds");
  }
  EXPECT_GT(rebuilds, 0) << "a strongly deforming lattice should trigger a rebuild";
}

/// A helical ramp ("spiral staircase" strip): all normals near +z, yet consecutive turns are
/// `pitch` apart — the classic false negative of normal-cone culling without contour test.
TriMesh helical_ramp(Scalar pitch, int turns = 3) {
  const Index nx = 60 * turns, ny = 3;
  TriMesh m = shapes::lattice(nx, ny);
  Positions x = m.positions();
  for (Vec3& p : x) {
    const Scalar theta = 2 * std::numbers::pi * turns * p.x();
    const Scalar r = 1 + 0.5 * p.y();
    p = Vec3(r * std::cos(theta), r * std::sin(theta), pitch * theta / (2 * std::numbers::pi));
  }
  m.set_positions(std::move(x));
  return m;
}

/// A narrow, steep valley: a sheet folded into a V whose walls approach each other slowly
/// towards the bottom (normals of each wall nearly constant, walls closer than h near the
/// bottom: the proximity pitfall of regularity culling).
TriMesh narrow_valley(Scalar half_gap) {
  TriMesh m = shapes::lattice(40, 20, 2.0, 1.0);
  Positions x = m.positions();
  for (Vec3& p : x) {
    const Scalar u = p.x() - 1;  // in [-1, 1]
    p = Vec3(half_gap * u + 0.001 * std::sin(9 * p.y()), p.y(), std::abs(u));
  }
  m.set_positions(std::move(x));
  return m;
}

TEST(ExactDetectors, AdversarialHelicalRamp) {
  for (Scalar pitch : {0.02, 0.05}) {
    const TriMesh m = helical_ramp(pitch);
    const auto frames = blend(m.positions(), testing::jitter(m.positions(), 0.005, 3), 2);
    const std::size_t n = expect_sequence_exact(m, frames, 0.04, all_specs());
    if (HasFatalFailure()) return;
    if (pitch < 0.04) {
      EXPECT_GT(n, 100u) << "turns closer than h must touch";
    }
  }
}

TEST(ExactDetectors, AdversarialNarrowValley) {
  const TriMesh m = narrow_valley(0.01);
  const auto frames = blend(m.positions(), testing::jitter(m.positions(), 0.002, 4), 2);
  const std::size_t n = expect_sequence_exact(m, frames, 0.02, all_specs());
  EXPECT_GT(n, 100u);
}

TEST(ExactDetectors, AdversarialCrumpledSheet) {
  const TriMesh sheet = shapes::lattice(40, 40);
  for (std::uint64_t seed : {21u}) {
    const Positions crumpled = testing::crumple_lattice(sheet, 0.35, seed);
    const std::vector<Positions> frames{crumpled, testing::jitter(crumpled, 0.01, seed)};
    const std::size_t n = expect_sequence_exact(sheet, frames, 0.02, default_specs());
    if (HasFatalFailure()) return;
    EXPECT_GT(n, 100u);
  }
}

// The k-DOP traversal tests its nodes in float: a scene far beyond the float range, one in its
// subnormal range and one far from the origin with a small thickness must give exactly naive's
// contacts all the same. Far beyond the double's comfortable range too (squares of 1e160
// overflow, of 1e-160 underflow): the detectors compute on the coordinates scaled by a power
// of two (detect/scale_detail.hpp), so every scale gives the contacts of scale 1 — the same
// counts, since multiplying by 10^j rounds each coordinate by at most half a unit in the last
// place, which moves no pair of this scene across h — except in the subnormal range, where the
// coordinates themselves lose bits (there exact methods must still equal naive). Before the
// scaling, naive itself found no TT contact at 1e150 and nothing at all from 1e160, and
// inflated TT to 750 at 1e-160; kdop:sweep=on found 626 TT to naive's 727 at 1e-150.
TEST(ExactDetectors, CoordinatesBeyondFloatPrecisionAndRange) {
  const TriMesh sheet = shapes::lattice(12, 12);
  const Positions crumpled = testing::crumple_lattice(sheet, 0.35, 5);
  struct Case {
    Scalar scale;
    Vec3 offset;
    bool same_counts;  // as at scale 1
  };
  const ContactKinds all = ContactKinds::parse("vf,ee,tt");
  std::vector<std::array<std::size_t, 3>> unit_counts;
  for (const Case& c : {Case{1, Vec3::Zero(), true}, Case{1e45, Vec3::Zero(), true}, Case{1e-42, Vec3::Zero(), true},
                        Case{1, Vec3(3e7, -3e7, 1e8), false}, Case{1e150, Vec3::Zero(), true},
                        Case{1e160, Vec3::Zero(), true}, Case{1e200, Vec3::Zero(), true},
                        Case{1e300, Vec3::Zero(), true}, Case{1e-150, Vec3::Zero(), true},
                        Case{1e-160, Vec3::Zero(), true}, Case{1e-200, Vec3::Zero(), true},
                        Case{1e-300, Vec3::Zero(), true}, Case{1e-310, Vec3::Zero(), false},
                        Case{1e-318, Vec3::Zero(), false}}) {
    SCOPED_TRACE("scale " + std::to_string(c.scale) + " (" + std::to_string(std::ilogb(c.scale)) + ") offset " +
                 std::to_string(c.offset.z()));
    std::vector<Positions> frames;
    for (const Positions& x : {crumpled, testing::jitter(crumpled, 0.01, 6)}) {
      Positions y(x.size());
      for (std::size_t i = 0; i < x.size(); ++i) y[i] = c.scale * x[i] + c.offset;
      frames.push_back(std::move(y));
    }
    const Scalar h = 0.03 * c.scale;
    const std::size_t n = expect_sequence_exact(sheet, frames, h, {"kdop", "kdop:sweep=on", "kdop:k=6", "hash", "sap"});
    if (HasFatalFailure()) return;
    EXPECT_GT(n, 20u);
    for (std::size_t i = 0; i < frames.size(); ++i) {
      const ContactSet want = run("naive", sheet, {}, frames[i], h, all);
      const std::array<std::size_t, 3> counts{want.vf.size(), want.ee.size(), want.tt.size()};
      if (unit_counts.size() < frames.size()) {
        unit_counts.push_back(counts);
        EXPECT_GT(counts[0] * counts[1] * counts[2], 0u) << "every kind should touch at scale 1";
      } else if (c.same_counts) {
        EXPECT_EQ(counts, unit_counts[i]) << "frame " << i << ": VF, EE, TT as at scale 1";
      }
    }
  }
}


Positions scaled_by(PositionsView x, int k) {
  Positions y(x.begin(), x.end());
  for (Vec3& p : y) {
    for (int a = 0; a < 3; ++a) p[a] = std::scalbn(p[a], k);
  }
  return y;
}

// Scaling the positions and the thickness by 2^k (exact while they stay in the normal range)
// changes no contact and scales every distance by 2^k, for every method (the stochastic ones
// with the same seed draw the same pairs), from far above the double's comfortable range to
// far below, and across frames whose scale jumps (the k-DOP tree and the orphan blocks keep
// coordinates from frame to frame: they start over when the detectors' scale changes). The
// crumpled lattice is moved into [1, 3]^3 so that every coordinate stays normal at 2^-1020.
TEST(ExactDetectors, PowerOfTwoScalesGiveTheSameContacts) {
  const TriMesh sheet = shapes::lattice(12, 12);
  Positions base = testing::crumple_lattice(sheet, 0.35, 5);
  for (Vec3& p : base) p += Vec3(1.5, 1.5, 1.5);
  const std::vector<Positions> unit{base, testing::jitter(base, 0.01, 6)};
  const Scalar h = 0.03;
  const ContactKinds all = ContactKinds::parse("vf,ee,tt");
  const std::vector<std::string> specs{"naive", "kdop",       "kdop:sweep=on", "hash", "sap",
                                       "stochastic",  "hybrid"};
  std::map<std::string, std::vector<ContactSet>> want;
  for (const std::string& spec : specs) {
    auto d = make(spec, h, all);
    d->set_topology(sheet.topology_ptr());
    for (std::size_t i = 0; i < unit.size(); ++i) {
      want[spec].emplace_back();
      d->update(i == 0 ? PositionsView() : PositionsView(unit[i - 1]), unit[i], want[spec].back());
    }
  }
  ASSERT_GT(want["naive"][0].tt.size(), 20u);
  ASSERT_GT(want["naive"][1].vf.size(), 20u);
  for (const int k : {-1020, -70, 64, 1000}) {
    SCOPED_TRACE("2^" + std::to_string(k));
    std::vector<Positions> frames;
    for (const Positions& x : unit) frames.push_back(scaled_by(x, k));
    for (const std::string& spec : specs) {
      auto d = make(spec, std::scalbn(h, k), all);
      d->set_topology(sheet.topology_ptr());
      for (std::size_t i = 0; i < frames.size(); ++i) {
        ContactSet got;
        d->update(i == 0 ? PositionsView() : PositionsView(frames[i - 1]), frames[i], got);
        expect_scaled(want[spec][i], got, k, spec + " frame " + std::to_string(i));
        if (HasFatalFailure()) return;
      }
    }
  }
  // One detector through frames whose scale jumps, compared with naive on each; the previous
  // frame is given as motion where it has the same scale (one power of two serves both: a
  // step from 1 to 2^-900 would put the current frame 2^-900 below the scale it is computed at).
  const std::vector<int> jump_scales{0, 0, 300, 300, 0, -900, -900, 1000, 0};
  std::vector<Positions> jumps;
  for (const int k : jump_scales) jumps.push_back(scaled_by(unit[jumps.size() % 2], k));
  for (const std::string spec : {"kdop", "kdop:sweep=on", "hash", "sap"}) {
    auto d = make(spec, h, all);
    d->set_topology(sheet.topology_ptr());
    std::size_t frame = 0;
    for (const int k : jump_scales) {
      SCOPED_TRACE(spec + " frame " + std::to_string(frame) + " at 2^" + std::to_string(k));
      // The thickness is the detector's: h at every scale, so compare with naive at h.
      const Positions& x = jumps[frame];
      ContactSet got, expected;
      const bool motion = frame > 0 && jump_scales[frame - 1] == k;
      d->update(motion ? PositionsView(jumps[frame - 1]) : PositionsView(), x, got);
      auto naive = make("naive", h, all);
      naive->set_topology(sheet.topology_ptr());
      naive->update(x, expected);
      expect_same(expected, got, "jump");
      if (HasFatalFailure()) return;
      ++frame;
    }
  }
}

// Positions whose non-zero coordinates span more than the double range cannot be scaled into
// it without losing bits: every method rejects them with an error that says so, never gives
// contacts of other positions. Spanning less is accepted, however far from 1.
TEST(ExactDetectors, PositionsSpanningBeyondTheDoubleRangeAreRejected) {
  const TriMesh sheet = shapes::lattice(4, 4);
  const Positions x = testing::crumple_lattice(sheet, 0.35, 5);
  Positions wide(x.size());
  for (std::size_t i = 0; i < x.size(); ++i) wide[i] = 1e300 * x[i];
  Positions accepted = wide;
  accepted[3] = Vec3(0.1, 1e-7, 0);  // 1e-307 of the largest: kept exactly
  wide[3] = Vec3(0, 1e-300, 0);
  for (const char* spec : {"naive", "kdop", "hash", "sap", "stochastic", "hybrid"}) {
    SCOPED_TRACE(spec);
    auto d = make(spec, 3e297, ContactKinds::parse("vf,ee,tt"));
    d->set_topology(sheet.topology_ptr());
    ContactSet out;
    out.tt.push_back({0, 1});
    try {
      d->update(wide, out);
      ADD_FAILURE() << "accepted";
    } catch (const InputError& e) {
      const std::string what = e.what();
      EXPECT_NE(what.find("span more than the double range"), std::string::npos) << what;
      EXPECT_NE(what.find("vertex 3's y coordinate 1e-300"), std::string::npos) << what;
    }
    EXPECT_TRUE(out.empty());
    EXPECT_NO_THROW(d->update(accepted, out));
    // The previous frame too, where the method uses it (the others ignore it).
    if (!d->capabilities().uses_motion) {
      EXPECT_NO_THROW(d->update(wide, accepted, out));
      continue;
    }
    try {
      d->update(wide, accepted, out);
      ADD_FAILURE() << "accepted";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("previous positions span"), std::string::npos) << e.what();
    }
  }
}

// A thickness far below or above the mesh's size (1e-200 and 1e100 of it): below, h^2
// underflows, yet pairs at distance 0 are contacts (0 < h); above, every pair is, without
// overflow in the broad phases. At scale 1 and far from it.
TEST(ExactDetectors, ThicknessFarBelowOrAboveTheMeshSize) {
  // Vertex 3 lies on face 0; edge (4, 5) crosses edge (1, 2) exactly; a third triangle apart.
  const TriMesh m = TriMesh::create({Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0), Vec3(0.25, 0.25, 0),
                                     Vec3(0.5, 0.5, -1), Vec3(0.5, 0.5, 1), Vec3(3, 3, 3), Vec3(4, 3, 3),
                                     Vec3(3, 4, 3)},
                                    {{0, 1, 2}, {3, 4, 5}, {6, 7, 8}});
  const ContactKinds all = ContactKinds::parse("vf,ee,tt");
  for (const Scalar scale : {1.0, 1e200, 1e-100}) {
    SCOPED_TRACE("scale " + std::to_string(std::ilogb(scale)));
    Positions x = m.positions();
    for (Vec3& p : x) p *= scale;
    const ContactSet tiny = run("naive", m, {}, x, 1e-200 * scale, all);
    EXPECT_EQ(tiny.vf.size(), 1u);  // vertex 3 on face 0
    EXPECT_EQ(tiny.ee.size(), 1u);  // (1, 2) through (4, 5)
    EXPECT_EQ(tiny.tt.size(), 1u);
    for (const auto& c : tiny.vf) EXPECT_EQ(c.distance, 0);
    expect_sequence_exact(m, {x}, 1e-200 * scale, {"kdop", "kdop:sweep=on", "hash", "sap"});
    if (HasFatalFailure()) return;
    const ContactSet huge = run("naive", m, {}, x, 1e100 * scale, all);
    EXPECT_EQ(huge.vf.size(), 3u * 3 * 2);  // every vertex against the two faces it is not in
    expect_sequence_exact(m, {x}, 1e100 * scale, {"kdop", "kdop:sweep=on", "hash", "sap"});
    if (HasFatalFailure()) return;
  }
  // 1e300 at scale 1 (and h = the largest double): in the scaled frame it is capped.
  expect_sequence_exact(m, {m.positions()}, std::numeric_limits<Scalar>::max(), {"kdop", "hash", "sap"});
}

// A vertex just under h above a face, far from the origin: the faces' padded slabs overlap by
// about 1e-6 h + 1e-9 |x|, far less than a float's spacing there, so the float lane test keeps
// the pair only because its conversion is monotone (a rounding towards the inside of the slabs
// loses the contact in these placements).
TEST(ExactDetectors, FloatLanesKeepPairsJustUnderTheThickness) {
  const Scalar h = 0.01;
  for (int k = 0; k < 40; ++k) {
    const Vec3 o = Vec3(1, 1.3, 0.7) * (1000 + 37.1 * k);
    const Scalar gap = h * (1 - 1e-9);
    const Vec3 v = o + Vec3(0.25, 0.25, gap);
    const TriMesh m = TriMesh::create({o, o + Vec3(1, 0, 0), o + Vec3(0, 1, 0), v, v + Vec3(1, 0, 1), v + Vec3(0, 1, 1)},
                                      {{0, 1, 2}, {3, 4, 5}});
    SCOPED_TRACE("placement " + std::to_string(k));
    const std::size_t n = expect_sequence_exact(m, {m.positions()}, h, {"kdop", "kdop:k=6", "kdop:leaf=1"},
                                                ContactKinds::parse("vf"));
    if (HasFatalFailure()) return;
    EXPECT_EQ(n, 1u);
  }
}

// The candidates' and orphans' box tests run in float lanes on the corners rounded to float,
// with pads widened to cover that rounding. Calls place(h, o, gap) on 100 placements on the float
// grid near 1024 (spacing u = 2^-13): o at a fraction t of a spacing from a grid point, a
// thickness of 81 + s spacings, and a gap just under h, upwards or downwards. A vertex gap above
// a face at o falls outside the face's box padded by the unwidened pad in 14 of them.
void for_each_rounding_placement(const std::function<void(Scalar, const Vec3&, Scalar)>& place) {
  const Scalar u = std::ldexp(1.0, -13);
  for (int ti = 0; ti < 10; ++ti) {
    for (const Scalar s : {0.1, 0.3, 0.5, 0.7, 0.9}) {
      for (const Scalar side : {1.0, -1.0}) {
        const Scalar h = (81 + s) * u;
        SCOPED_TRACE("t " + std::to_string(ti) + " s " + std::to_string(s) + " side " + std::to_string(side));
        place(h, Vec3(512, 256, 1024 + (0.05 + 0.1 * ti) * u), side * h * (1 - 1e-9));
        if (::testing::Test::HasFailure()) return;
      }
    }
  }
}

TEST(ExactDetectors, FloatBoxTestsCoverTheRounding) {
  std::size_t placements = 0;
  for_each_rounding_placement([&](Scalar h, const Vec3& o, Scalar gap) {
    const Scalar side = gap > 0 ? 1 : -1;
    // Vertex 3 over face 0.
    const Vec3 v = o + Vec3(0.25, 0.25, gap);
    const TriMesh vf = TriMesh::create(
        {o, o + Vec3(1, 0, 0), o + Vec3(0, 1, 0), v, v + Vec3(1, 0, side), v + Vec3(0, 1, side)}, {{0, 1, 2}, {3, 4, 5}});
    EXPECT_EQ(expect_sequence_exact(vf, {vf.positions()}, h, {"kdop", "hash", "sap"}, ContactKinds::parse("vf")), 1u);
    // Side (0, 1) of face 0 along x, side (3, 4) of face 1 along y, crossing gap above it; the
    // third corners lean away.
    const Vec3 w = o + Vec3(0, 0, gap);
    const TriMesh ee = TriMesh::create({o + Vec3(-0.5, 0, 0), o + Vec3(0.5, 0, 0), o + Vec3(0, -1, -side),
                                        w + Vec3(0, -0.5, 0), w + Vec3(0, 0.5, 0), w + Vec3(1, 0, side)},
                                       {{0, 1, 2}, {3, 4, 5}});
    EXPECT_EQ(expect_sequence_exact(ee, {ee.positions()}, h, {"kdop", "hash", "sap"}, ContactKinds::parse("ee")), 1u);
    ++placements;
  });
  EXPECT_EQ(placements, 100u);
}

// The same for the orphans (sub-pairs of faces that share a vertex), whose box tests run in
// float lanes on the frames that do not refresh their bounds: two faces sharing a corner.
TEST(ExactDetectors, FloatBoxTestsOfOrphansCoverTheRounding) {
  std::size_t placements = 0;
  for_each_rounding_placement([&](Scalar h, const Vec3& o, Scalar gap) {
    // Vertex 3 over face 0; side (3, 4) crosses over side (1, 2), and side (0, 4) too.
    const TriMesh m = TriMesh::create(
        {o, o + Vec3(1, 0, 0), o + Vec3(0, 1, 0), o + Vec3(0.3, 0.3, gap), o + Vec3(0.8, 0.8, gap)},
        {{0, 1, 2}, {0, 3, 4}});
    // Identical frames: the first refreshes the orphans' bounds, the next ones test them.
    const std::vector<Positions> frames(3, m.positions());
    EXPECT_EQ(expect_sequence_exact(m, frames, h, {"kdop", "hash", "sap"}, ContactKinds::parse("vf,ee")), 9u);
    ++placements;
  });
  EXPECT_EQ(placements, 100u);
}

TEST(ExactDetectors, IsolatedVerticesAndDegenerateFaces) {
  // Vertex 3 is used by no face and hovers over face 0; vertex 7 is isolated and far; face 2 is
  // degenerate (collinear corners) and close to face 0; vertex 8 duplicates vertex 0's position.
  const TriMesh m = TriMesh::create(
      {Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0), Vec3(0.2, 0.2, 0.01), Vec3(0.1, 0.1, 0.02),
       Vec3(0.6, 0.1, 0.02), Vec3(1.1, 0.1, 0.02), Vec3(5, 5, 5), Vec3(0, 0, 0), Vec3(2, 0, 0.005),
       Vec3(2, 1, 0.005)},
      {{0, 1, 2}, {4, 5, 9}, {4, 5, 6}, {8, 9, 10}});
  const std::vector<Positions> frames{m.positions(), testing::jitter(m.positions(), 0.004, 9)};
  const std::size_t n = expect_sequence_exact(m, frames, 0.05, all_specs());
  EXPECT_GT(n, 3u);
}

TEST(ExactDetectors, ContactKindsSubsetsAndZeroThickness) {
  const shapes::FoldedClothParams params{.n = 16};
  const TriMesh m = shapes::folded_cloth(params);
  const std::vector<Positions> frames{m.positions()};
  for (const char* kinds : {"vf", "ee", "tt", "vf,tt"}) {
    SCOPED_TRACE(kinds);
    expect_sequence_exact(m, frames, params.thickness, default_specs(), ContactKinds::parse(kinds));
  }
  // h = 0: no proximity contact, intersections still found.
  const TriMesh lattice = shapes::lattice(16, 16);
  const Positions x = testing::crumple_lattice(lattice, 0.4, 3);
  expect_sequence_exact(lattice, {x}, 0.0, default_specs());
}

// ---- contact buffer cap --------------------------------------------------------------------

// KdopParams built in code (not through a method spec) get the same range checks: a leaf of
// more than 64 faces would overrun the 64-bit member masks.
TEST(ExactDetectors, KdopParamsOutOfRangeAreRejected) {
  const auto make_with = [](auto set) {
    KdopParams p;
    set(p);
    return KdopTree(p);
  };
  EXPECT_NO_THROW(make_with([](KdopParams& p) { p.leaf = 64; }));
  EXPECT_THROW(make_with([](KdopParams& p) { p.leaf = 65; }), InputError);
  EXPECT_THROW(make_with([](KdopParams& p) { p.leaf = 0; }), InputError);
  EXPECT_THROW(make_with([](KdopParams& p) { p.arity = 3; }), InputError);
  EXPECT_THROW(make_with([](KdopParams& p) { p.k = 10; }), InputError);
  EXPECT_THROW(make_with([](KdopParams& p) { p.rebuild = 0.5; }), InputError);
  // One rule, two callers: each names itself and the offending value.
  const auto message = [](const std::function<void()>& f) -> std::string {
    try {
      f();
    } catch (const InputError& e) {
      return e.what();
    }
    return "no error";
  };
  EXPECT_NE(message([&] { make_with([](KdopParams& p) { p.leaf = 65; }); }).find("kdop: leaf must be in 1..64, got 65"),
            std::string::npos);
  EXPECT_NE(message([] { KdopParams::from_spec(MethodSpec::parse("kdop:leaf=65")); })
                .find("method kdop:leaf=65: leaf must be in 1..64, got 65"),
            std::string::npos);
  EXPECT_NE(message([] { KdopParams::from_spec(MethodSpec::parse("kdop:leaf=99999999999")); }).find("leaf must be in 1..64"),
            std::string::npos);
}

TEST(ExactDetectors, OverflowIsReportedNeverSilent) {
  const shapes::FoldedClothParams params{.n = 16};
  const TriMesh m = shapes::folded_cloth(params);
  const ContactSet all = run("naive", m, {}, m.positions(), params.thickness);
  ASSERT_GT(all.size(), 20u);
  for (const std::string& base : default_specs()) {
    SCOPED_TRACE(base);
    // Default: throw.
    auto d = make(base + ":max_contacts=10", params.thickness);
    d->set_topology(m.topology_ptr());
    ContactSet out;
    EXPECT_THROW(d->update(m.positions(), out), ContactOverflowError);
    EXPECT_TRUE(static_cast<ExactDetector&>(*d).overflowed());
    // Truncate: the first contacts in canonical order, flagged in stats.
    auto t = make(base + ":max_contacts=10,overflow=truncate", params.thickness);
    t->set_topology(m.topology_ptr());
    t->update(m.positions(), out);
    EXPECT_EQ(out.size(), 10u);
    EXPECT_TRUE(static_cast<ExactDetector&>(*t).overflowed());
    EXPECT_EQ(t->stats().get("overflow"), 1);
    EXPECT_EQ(t->stats().get("contacts_dropped"), static_cast<double>(all.size() - 10));
    ContactSet first = all;
    first.vf.resize(std::min<std::size_t>(10, first.vf.size()));
    first.ee.resize(10 - first.vf.size());
    expect_same(first, out, "truncated");
    // A cap that is not reached: everything, no flag.
    auto c = make(base + ":max_contacts=" + std::to_string(all.size()), params.thickness);
    c->set_topology(m.topology_ptr());
    c->update(m.positions(), out);
    EXPECT_EQ(out.size(), all.size());
    EXPECT_FALSE(static_cast<ExactDetector&>(*c).overflowed());
    EXPECT_EQ(c->stats().get("overflow"), 0);
  }
}

TEST(ExactDetectors, SpecsAreValidated) {
  for (const char* bad : {"kdop:k=10", "kdop:arity=3", "kdop:leaf=0", "kdop:rebuild=0.5", "kdop:sweep=maybe", "hash:cell=-1",
                          "hash:table=-5", "sap:axis=w", "kdop:max_contacts=-1", "sap:overflow=drop"}) {
    SCOPED_TRACE(bad);
    EXPECT_THROW(make(bad, 0.1), InputError);
  }
  EXPECT_TRUE(method_info(Method::Kdop).capabilities.exact);
  EXPECT_TRUE(method_info(Method::Hash).capabilities.exact);
  EXPECT_TRUE(method_info(Method::Sap).capabilities.exact);
  EXPECT_TRUE(method_info(Method::Kdop).capabilities.uses_motion);
}

// ---- real meshes ---------------------------------------------------------------------------

TEST(ExactDetectors, SmallRealMeshesAgainstNaive) {
  const char* files[] = {"ipc-toolkit-tests/bunny.ply", "ipc-toolkit-tests/height-field.ply",
                         "ipc-toolkit-tests/cube.ply", "ipc-toolkit-tests/two-cubes-far.ply",
                         "ipc-toolkit-tests/two-cubes-close.ply", "ipc-toolkit-tests/two-cubes-intersecting.ply"};
  for (const char* file : files) {
    SCOPED_TRACE(file);
    const TriMesh m = io::read_mesh(testing::data_path(file));
    const Scalar diag = compute_bounds(m.positions()).diagonal();
    const std::vector<Positions> frames{m.positions(), testing::jitter(m.positions(), 1e-3 * diag, 7)};
    // The two larger meshes (~5k faces) at one thickness only: naive is the cost here.
    const bool large = m.num_faces() > 1000;
    if (large && kSanitized) continue;  // naive under sanitizers: minutes
    for (double rel : {1e-3, 1e-2}) {
      if (large && rel != (std::string(file).find("bunny") != std::string::npos ? 1e-2 : 1e-3)) continue;
      expect_sequence_exact(m, frames, rel * diag, default_specs());
      if (HasFatalFailure()) return;
    }
  }
  // The two steps of the thick cloth, with the real motion between them.
  const TriMesh t0 = io::read_mesh(testing::data_path("ipc-toolkit-tests/thick-cloth/t0.ply"));
  const TriMesh t1 = io::read_mesh(testing::data_path("ipc-toolkit-tests/thick-cloth/t1.ply"));
  const Scalar diag = compute_bounds(t0.positions()).diagonal();
  for (double rel : {1e-3, 1e-2}) {
    expect_sequence_exact(t0, {t0.positions(), t1.positions()}, rel * diag, all_specs());
  }
}

/// FNV-1a 64 of every byte written to it, without keeping them: the contact text of one frame
/// at 1e-2 is hundreds of MB.
class Fnv1aBuf : public std::streambuf {
 public:
  std::uint64_t hash() const { return h_; }

 protected:
  int_type overflow(int_type c) override {
    if (!traits_type::eq_int_type(c, traits_type::eof())) add(static_cast<unsigned char>(traits_type::to_char_type(c)));
    return traits_type::not_eof(c);
  }
  std::streamsize xsputn(const char* s, std::streamsize n) override {
    for (std::streamsize i = 0; i < n; ++i) add(static_cast<unsigned char>(s[i]));
    return n;
  }

 private:
  void add(unsigned char c) {
    h_ ^= c;
    h_ *= 1099511628211ull;
  }
  std::uint64_t h_ = 1469598103934665603ull;
};

struct RealScene {
  std::string frame0, frame1;
};

const std::map<std::string, RealScene>& real_scenes() {
  static const std::map<std::string, RealScene> scenes{
      {"cloth-ball", {"sample-scalable-ccd/cloth-ball/frames/cloth_ball92.ply", "sample-scalable-ccd/cloth-ball/frames/cloth_ball93.ply"}},
      {"cloth-funnel", {"sample-scalable-ccd/cloth-funnel/frames/227.ply", "sample-scalable-ccd/cloth-funnel/frames/228.ply"}},
      {"rod-twist", {"sample-scalable-ccd/rod-twist/frames/3036.ply", "sample-scalable-ccd/rod-twist/frames/3037.ply"}},
      {"armadillo-rollers", {"sample-scalable-ccd/armadillo-rollers/frames/326.ply", "sample-scalable-ccd/armadillo-rollers/frames/327.ply"}},
      {"n-body", {"sample-scalable-ccd/n-body-simulation/frames/balls16_18.ply", "sample-scalable-ccd/n-body-simulation/frames/balls16_19.ply"}},
  };
  return scenes;
}

struct Reference {
  std::string scene, file, rel;
  std::size_t vf = 0, ee = 0;
  std::string hash;
};

std::vector<Reference> read_references() {
  std::ifstream in(std::string(CRUMPLE_TEST_SOURCE_DIR) + "/data/reference/real_meshes.txt");
  std::vector<Reference> out;
  std::string line;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#') continue;
    std::istringstream s(line);
    Reference r;
    s >> r.scene >> r.file >> r.rel >> r.vf >> r.ee >> r.hash;
    if (s) out.push_back(r);
  }
  return out;
}

/// Every cached naive reference (scene, frame, thickness) reproduced by the exact detectors:
/// frame 0 without motion, frame 1 with the motion from frame 0, through one detector (so
/// the persistent state of frame 0 is reused). `kdop` (the default) on every reference; the
/// other detectors on every reference at 1e-3, and at 1e-2 on alternate scenes (the n-th scene
/// that has references at the thickness: `hash` and `kdop:sweep=on` on even n, `sap` on odd n),
/// so that each of them still meets real meshes at every thickness run, millions of contacts per
/// frame at 1e-2 included. When `sanitized`: 1e-3 only, and the other detectors only on the
/// scenes of under 100,000 contacts a frame (three of five; writing the contacts' text for the
/// hash is most of the time there), `kdop` still on every scene.
void check_real_references(bool sanitized) {
  const std::vector<Reference> refs = read_references();
  ASSERT_FALSE(refs.empty()) << "tests/data/reference/real_meshes.txt missing or empty";
  // The defaults, and the motion-covering hierarchy (frame 1 comes with the motion).
  std::vector<std::string> specs = default_specs();
  specs.push_back("kdop:sweep=on");
  std::map<std::string, std::size_t> checked;  // frames per spec
  for (const char* rel : {"0.001", "0.01"}) {
    const bool large = std::string(rel) == "0.01";  // millions of contacts per frame
    if (large && sanitized) continue;
    std::size_t nth = 0;  // scenes with references at this thickness so far
    for (const auto& [scene, files] : real_scenes()) {
      std::vector<const Reference*> mine(2, nullptr);
      for (const Reference& r : refs) {
        if (r.scene != scene || r.rel != rel) continue;
        const std::string base0 = files.frame0.substr(files.frame0.find_last_of('/') + 1);
        mine[r.file == base0 ? 0 : 1] = &r;
      }
      if (!mine[0] || !mine[1]) continue;
      const TriMesh m0 = io::read_mesh(testing::data_path(files.frame0));
      const Positions x1 = io::read_mesh(testing::data_path(files.frame1)).positions();
      const Scalar diag = compute_bounds(m0.positions()).diagonal();
      const std::size_t contacts = std::max(mine[0]->vf + mine[0]->ee, mine[1]->vf + mine[1]->ee);
      for (std::size_t k = 0; k < specs.size(); ++k) {
        const std::string& spec = specs[k];
        const bool rotate = large && !std::getenv("CRUMPLE_ALL_REFERENCES");
        if (k != 0 && rotate && (nth + k) % 2 == 0) continue;
        if (k != 0 && sanitized && contacts >= 100000) continue;
        SCOPED_TRACE(scene + " rel " + rel + " " + spec);
        auto d = make(spec, std::stod(rel) * diag);
        d->set_topology(m0.topology_ptr());
        ContactSet out;
        for (int frame = 0; frame < 2; ++frame) {
          if (frame == 0) {
            d->update(m0.positions(), out);
          } else {
            d->update(m0.positions(), x1, out);
          }
          Fnv1aBuf hashed;
          std::ostream text(&hashed);
          write_contacts(text, out);
          char hash[32];
          std::snprintf(hash, sizeof hash, "%016llx", static_cast<unsigned long long>(hashed.hash()));
          EXPECT_EQ(out.vf.size(), mine[static_cast<std::size_t>(frame)]->vf) << "frame " << frame;
          EXPECT_EQ(out.ee.size(), mine[static_cast<std::size_t>(frame)]->ee) << "frame " << frame;
          EXPECT_EQ(std::string(hash), mine[static_cast<std::size_t>(frame)]->hash) << "frame " << frame;
          ++checked[spec];
        }
      }
      ++nth;
    }
  }
  for (const std::string& spec : specs) {
    EXPECT_GE(checked[spec], 4u) << spec;  // two scenes at least, both frames
    std::printf("[ exact    ] %s: %zu cached reference frames reproduced\n", spec.c_str(), checked[spec]);
  }
}

/// Release: every detector on every 1e-3 reference, and at 1e-2 (millions of contacts per
/// frame) `kdop` on both scenes and the others on one each (CRUMPLE_ALL_REFERENCES=1 in the
/// environment: all of them on both). Under sanitizers 1e-3 only, the others on the three
/// scenes of under 100,000 contacts.
TEST(ExactDetectors, RealMeshesMatchCachedNaiveReferences) { check_real_references(kSanitized); }

// A TT-only query streams the broad phase's candidates to the narrow phase on the broad
// phase's threads, and gathers triangle contacts from their keys alone (exact/gather_contacts.cpp):
// element by element naive's, for every method, on one and three threads, on a crumpled
// sheet moving over frames and on triangles of which every pair meets (more candidates than
// one stream chunk holds).
TEST(ExactDetectors, TriangleIntersectionsAloneMatchNaive) {
  const TriMesh sheet = shapes::lattice(24, 24);
  std::vector<Positions> frames{testing::crumple_lattice(sheet, 0.3, 3)};
  for (int f = 1; f < 3; ++f) {
    frames.push_back(frames.back());
    for (Vec3& p : frames.back()) p = Vec3(p.x() + 0.01 * p.z(), p.y(), p.z() * 0.97);
  }
  const ContactKinds tt = ContactKinds::parse("tt");
  EXPECT_GT(expect_sequence_exact(sheet, frames, 0.0, all_specs(), tt, {1, 3}), 50u) << "the sheet should cross itself";
  const auto [spikes, x] = testing::hedgehog(kSanitized ? 120 : 240, false);
  EXPECT_EQ(expect_sequence_exact(spikes, {x}, 0.0, default_specs(), tt, {1, 3}),
            static_cast<std::size_t>(spikes.num_faces()) * (spikes.num_faces() - 1) / 2);
}

/// Published fact (tests/data README, the dataset's paper): cloth-ball 93 has 97,320
/// non-adjacent intersecting triangle pairs.
TEST(ExactDetectors, ClothBallIntersectionCount) {
  if (kSanitized) GTEST_SKIP() << "large mesh: Release only";
  const TriMesh m0 = io::read_mesh(testing::data_path(real_scenes().at("cloth-ball").frame0));
  const Positions x1 = io::read_mesh(testing::data_path(real_scenes().at("cloth-ball").frame1)).positions();
  for (const std::string& spec : default_specs()) {
    const ContactSet c = run(spec, m0, m0.positions(), x1, 0.0, ContactKinds::parse("tt"));
    EXPECT_EQ(c.tt.size(), 97320u) << spec;
  }
}

// Issue 45: listing the orphan sub-pairs went through `face_faces`, whose size is the square of
// the faces around a vertex: n repeated faces (no orphan at all) cost n^2 entries. The
// topology holds no more after a detection than before, and the contacts are naive's.
TEST(ExactDetectors, RepeatedFacesNeedNoQuadraticAdjacency) {
  Positions positions{Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0)};
  std::vector<Face> faces(2000, Face{0, 1, 2});
  const TriMesh mesh = TriMesh::create(std::move(positions), std::move(faces));
  const std::size_t before = mesh.topology().memory_bytes();
  const ContactSet want = run("naive", mesh, {}, mesh.positions(), 0.01);
  for (const std::string spec : {"kdop", "hash", "sap"}) {
    const ContactSet got = run(spec, mesh, {}, mesh.positions(), 0.01);
    expect_same(want, got, spec);
    EXPECT_EQ(mesh.topology().memory_bytes(), before) << spec;
  }
}


/// A fan of n triangles around one centre vertex (the last vertex, so that a pair of faces
/// next to each other has a rim vertex as its smallest shared one), its rim a conical helix of
/// `turns` turns whose successive turns are `pitch` apart along z, each rim vertex at
/// `radius`, jittered by `jitter` (seeded).
TriMesh helix_fan(Index n, Scalar turns, Scalar pitch, Scalar jitter, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<Scalar> u(-jitter, jitter);
  Positions x;
  for (Index k = 0; k <= n; ++k) {
    const Scalar a = 2 * std::numbers::pi * turns * static_cast<Scalar>(k) / static_cast<Scalar>(n);
    x.emplace_back(std::cos(a) + u(rng), std::sin(a) + u(rng), pitch * a / (2 * std::numbers::pi) + u(rng));
  }
  x.emplace_back(0, 0, 0);
  std::vector<Face> faces;
  for (Index k = 0; k < n; ++k) faces.push_back({k, k + 1, n + 1});
  return TriMesh::create(std::move(x), std::move(faces));
}

// Issue 45: the orphan sub-pairs around a vertex of high valence (a star) are found each frame
// among the faces that come close, not listed (a list is quadratic in the valence). Two turns
// of a fan 0.6h apart, so that rim vertices and edges touch the faces of the other turn, and a
// bicone (two stars sharing the rim): every method, every thread count, exactly naive's.
TEST(ExactDetectors, StarOrphansMatchNaive) {
  const Scalar h = 0.05;
  const TriMesh fan = helix_fan(240, 2, 0.6 * h, 0.1 * h, 7);
  Positions twisted = fan.positions();
  for (Vec3& p : twisted) p = Vec3(p.x() - 0.02 * p.y(), p.y() + 0.02 * p.x(), p.z() * 0.9);
  const std::size_t n = expect_sequence_exact(fan, {fan.positions(), twisted}, h, default_specs(),
                                              ContactKinds::parse("vf,ee,tt"), {1, 3});
  if (HasFatalFailure()) return;
  EXPECT_GT(n, 300u) << "the turns should touch";
  auto d = make("kdop", h, ContactKinds::parse("vf,ee"));
  d->set_topology(fan.topology_ptr());
  ContactSet out;
  d->update(fan.positions(), out);
  EXPECT_EQ(d->stats().get("orphan_stars"), 1);
  EXPECT_GT(d->stats().get("orphan_star_pairs"), 0);

  // Bicone: rim 0..n-1 on a circle, poles n (top) and n+1 (bottom) 0.4h above and below.
  const Index m = 100;
  Positions x;
  for (Index k = 0; k < m; ++k) {
    const Scalar a = 2 * std::numbers::pi * static_cast<Scalar>(k) / static_cast<Scalar>(m);
    x.emplace_back(std::cos(a), std::sin(a), 0);
  }
  x.emplace_back(0.01, 0, 0.4 * h);
  x.emplace_back(0, 0.01, -0.4 * h);
  std::vector<Face> faces;
  for (Index k = 0; k < m; ++k) {
    faces.push_back({k, (k + 1) % m, m});
    faces.push_back({(k + 1) % m, k, m + 1});
  }
  const TriMesh bicone = TriMesh::create(std::move(x), std::move(faces));
  EXPECT_GT(expect_sequence_exact(bicone, {bicone.positions()}, h, all_specs(), ContactKinds::parse("vf,ee"), {1, 3}),
            100u);
}

// Issue 45: detection on a fan, or on copies of one face, costs work linear in the faces (the
// thickness a fixed share of the rim spacing, so that the contacts are too): the listed
// sub-pairs and the star's examined face pairs no more than double when the faces double.
// Listing them all was quadratic (a 16,000-triangle fan took 14 GB).
TEST(ExactDetectors, StarWorkIsLinearInTheValence) {
  const auto work = [](const TriMesh& mesh, Scalar h) {
    auto d = make("kdop", h, ContactKinds::parse("vf,ee"));
    d->set_topology(mesh.topology_ptr());
    ContactSet out;
    d->update(mesh.positions(), out);
    const DetectorStats& st = d->stats();
    return st.get("orphan_vf") + st.get("orphan_ee") + st.get("orphan_star_pairs");
  };
  const auto spacing = [](Index n) { return 2 * std::numbers::pi / static_cast<Scalar>(n); };
  const Scalar fan_small = work(helix_fan(1000, 1, 0, 0, 1), 2 * spacing(1000));
  const Scalar fan_large = work(helix_fan(2000, 1, 0, 0, 1), 2 * spacing(2000));
  EXPECT_GT(fan_small, 1000);
  EXPECT_LE(fan_large, 2.2 * fan_small);
  const auto copies = [](Index n) {
    return TriMesh::create({Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0)}, std::vector<Face>(n, Face{0, 1, 2}));
  };
  const Scalar copies_small = work(copies(1000), 0.01), copies_large = work(copies(2000), 0.01);
  EXPECT_LE(copies_large, 2.2 * copies_small + 100);
}

}  // namespace
}  // namespace crumple
