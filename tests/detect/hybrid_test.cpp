// The hybrid detector (docs/hybrid.md): stochastic search inside the zones of a coarse
// hierarchy. Checked against the exact reference on seeded sequences: never a false contact
// (every reported contact is in naive's set with the same distance bit for bit), every zone
// examined within `every` frames (counted per zone, frame by frame), work that stops at a budget
// counted in zones and resumes where it stopped, a saved state that replays and continues bit
// for bit, recall floors set below measured values, and `search=exact` finding everything.
#include <crumple/core/error.hpp>
#include <crumple/detect/compare.hpp>
#include <crumple/detect/detector.hpp>
#include <crumple/detect/hybrid.hpp>
#include <crumple/mesh/shapes.hpp>
#include <crumple/sim/scene.hpp>
#include <support/run_cache.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <ctime>
#include <map>
#include <set>
#include <tuple>

namespace crumple {
namespace {

std::unique_ptr<Detector> make(const std::string& spec, Scalar h, ContactKinds kinds = {}) {
  return make_detector(MethodSpec::parse(spec), {.thickness = h, .kinds = kinds});
}

HybridDetector& as_hybrid(Detector& d) { return dynamic_cast<HybridDetector&>(d); }

/// The folding sequence (detect/compare.hpp): 16 × 16 lattice, 40 frames, contact growing from
/// none to a few hundred contacts a frame. Fewer frames under sanitizers.
const FoldingSequence& folding() {
#ifdef CRUMPLE_SANITIZED
  static const FoldingSequence s({.n = 16, .frames = 20, .seed = 7});
#else
  static const FoldingSequence s({.n = 16, .frames = 40, .seed = 7});
#endif
  return s;
}

/// Frames 120..219 (..159 under sanitizers) of the simulator's `hanging-cloth` (the thesis'
/// scene: a 10×10 cloth falling through itself, 15–55% of the edges in collision).
/// Recorded once per build of this program (support/run_cache.hpp).
const VectorFrames& cloth() {
#ifdef CRUMPLE_SANITIZED
  constexpr std::int64_t kLast = 159;
#else
  constexpr std::int64_t kLast = 219;
#endif
  static const VectorFrames f =
      testing::cached_frames("hanging-cloth-1-120-" + std::to_string(kLast), "hanging-cloth", [] {
        sim::Recording r = sim::record_scene("hanging-cloth", kLast, 1);
        std::vector<Positions> kept(r.frames.begin() + 120, r.frames.end());
        return VectorFrames(std::move(r.mesh), std::move(kept), "hanging-cloth");
      });
  return f;
}

Scalar cloth_thickness() {
  return sim::make_scene(sim::SceneSpec::parse("hanging-cloth"), 1).settings.detector.thickness;
}

const ReferenceRun& reference(const FrameSource& frames, Scalar h, ContactKinds kinds = {}) {
  static std::map<std::tuple<const FrameSource*, bool, bool, bool>, ReferenceRun> cache;
  const auto key = std::make_tuple(&frames, kinds.vf, kinds.ee, kinds.tt);
  auto it = cache.find(key);
  if (it == cache.end()) {
    // Once per build of this program too (support/run_cache.hpp): each test runs in a process of its own.
    it = cache.emplace(key, testing::cached_naive_reference(frames, h, kinds)).first;
  }
  return it->second;
}

/// Every reported contact is in the reference with identical fields.
void expect_true_contacts(const ContactSet& got, const ContactSet& ref, std::size_t frame) {
  std::map<std::pair<Index, Index>, const VertexFaceContact*> vf;
  for (const auto& c : ref.vf) vf[{c.vertex, c.face}] = &c;
  std::map<std::pair<Edge, Edge>, const EdgeEdgeContact*> ee;
  for (const auto& c : ref.ee) ee[{c.a, c.b}] = &c;
  std::set<std::pair<Index, Index>> tt;
  for (const auto& c : ref.tt) tt.insert({c.face0, c.face1});
  for (const auto& c : got.vf) {
    const auto it = vf.find({c.vertex, c.face});
    ASSERT_NE(it, vf.end()) << "false VF contact " << c.vertex << " " << c.face << ", frame " << frame;
    EXPECT_EQ(c.distance, it->second->distance);
    EXPECT_EQ(c.barycentric, it->second->barycentric);
    EXPECT_EQ(c.normal, it->second->normal);
  }
  for (const auto& c : got.ee) {
    const auto it = ee.find({c.a, c.b});
    ASSERT_NE(it, ee.end()) << "false EE contact, frame " << frame;
    EXPECT_EQ(c.distance, it->second->distance);
    EXPECT_EQ(c.s, it->second->s);
    EXPECT_EQ(c.t, it->second->t);
    EXPECT_EQ(c.normal, it->second->normal);
  }
  for (const auto& c : got.tt) ASSERT_TRUE(tt.count({c.face0, c.face1})) << "false TT contact, frame " << frame;
}

/// Runs `spec` over the frames (with the previous positions, as a simulation gives them),
/// checking every frame for false contacts; returns the totals against the reference.
ContactMatch run(const std::string& spec, const FrameSource& frames, Scalar h, ContactKinds kinds = {},
                 const std::function<void(Detector&, std::size_t)>& each = {}) {
  const ReferenceRun& ref = reference(frames, h, kinds);
  auto d = make(spec, h, kinds);
  d->set_topology(frames.mesh().topology_ptr());
  ContactMatch total;
  Positions previous;
  ContactSet got;
  for (std::size_t i = 0; i < frames.size(); ++i) {
    const Positions x = frames.positions(i);
    d->update(previous.empty() ? PositionsView{} : PositionsView(previous), x, got);
    expect_true_contacts(got, ref.contacts[i], i);
    total += match_contacts(got, ref.contacts[i]);
    if (each) each(*d, i);
    previous = x;
  }
  return total;
}

TEST(HybridParams, ParsesDefaultsAndErrors) {
  const HybridParams bare = HybridParams::from_spec(MethodSpec::parse("hybrid"));
  EXPECT_TRUE(bare == HybridParams{});
  const HybridParams p = HybridParams::from_spec(MethodSpec::parse(
      "hybrid:leaf=32,every=3,budget=2.5,zones=7,search=exact,draw=5,propagation=full,near=3,steps=4,seed=9"));
  EXPECT_EQ(p.leaf, 32);
  EXPECT_EQ(p.every, 3);
  EXPECT_EQ(p.budget_ms, 2.5);
  EXPECT_EQ(p.zones, 7);
  EXPECT_EQ(p.search, ZoneSearch::Exact);
  EXPECT_EQ(p.draw, 5);
  EXPECT_FALSE(p.auto_propagation);
  EXPECT_EQ(p.propagation, Propagation::Full);
  EXPECT_TRUE(HybridParams::from_spec(MethodSpec::parse("hybrid:propagation=auto")).auto_propagation);
  EXPECT_EQ(p.near, 3);
  EXPECT_EQ(p.steps, 4);
  EXPECT_EQ(p.seed, 9u);
  EXPECT_TRUE(HybridParams::from_spec(MethodSpec::parse(p.to_string())) == p) << p.to_string();
  for (const char* bad : {"hybrid:leaf=3", "hybrid:every=0", "hybrid:budget=-1", "hybrid:zones=-2",
                          "hybrid:search=random", "hybrid:near=0.5", "hybrid:steps=0", "hybrid:seed=-1",
                          "hybrid:draw=-1", "hybrid:budget=inf"}) {
    EXPECT_THROW(HybridParams::from_spec(MethodSpec::parse(bad)), InputError) << bad;
  }
  EXPECT_TRUE(method_info(Method::Hybrid).capabilities.stochastic);
  EXPECT_FALSE(method_info(Method::Hybrid).capabilities.exact);
}

TEST(Hybrid, LeavesPartitionTheFaces) {
  const TriMesh& mesh = folding().mesh();
  auto d = make("hybrid:leaf=20", folding().thickness());
  d->set_topology(mesh.topology_ptr());
  const HybridDetector& h = as_hybrid(*d);
  std::vector<int> seen(static_cast<std::size_t>(mesh.num_faces()), 0);
  for (Index l = 0; l < h.num_leaves(); ++l) {
    EXPECT_LE(h.leaf_faces(l).size(), 20u);
    EXPECT_GE(h.leaf_faces(l).size(), 1u);
    for (const Index f : h.leaf_faces(l)) ++seen[static_cast<std::size_t>(f)];
  }
  for (const int s : seen) ASSERT_EQ(s, 1);
  EXPECT_LE(h.num_leaves(), mesh.num_faces() / 20 * 2) << "patches are mostly full";
}

// With every zone searched exhaustively, the hybrid finds exactly the reference: the zones
// cover every contact (a pair closer than the near distance lies in its owners' zone).
TEST(Hybrid, ExactZoneSearchFindsEveryContact) {
  const ContactMatch m = run("hybrid:search=exact", folding(), folding().thickness(), ContactKinds::parse("vf,ee,tt"));
  EXPECT_GT(m.reference, 1000u);
  EXPECT_EQ(m.missed, 0u);
  EXPECT_EQ(m.false_contacts, 0u);
  const ContactMatch c = run("hybrid:search=exact,leaf=16", cloth(), cloth_thickness());
  EXPECT_GT(c.reference, 1000u);
  EXPECT_EQ(c.missed, 0u);
}

// Recall floors of the stochastic zone search, set a few points below the values measured when
// they were written (in the comments); a search that forgets zones or draws badly falls below.
TEST(Hybrid, RecallAboveMeasuredFloorsAndNoFalseContact) {
  struct Floor {
    const char* spec;
    double folding, cloth;
  };
  const Floor floors[] = {
      {"hybrid", 0.97, 0.98},                           // measured 0.9942, 1.0000
      {"hybrid:propagation=auto", 0.93, 0.90},          // measured 0.9649, 0.9369
      {"hybrid:draw=2,propagation=none", 0.78, 0.58},   // measured 0.8191, 0.6231
  };
  for (const Floor& f : floors) {
    SCOPED_TRACE(f.spec);
    const ContactMatch a = run(f.spec, folding(), folding().thickness());
    const ContactMatch b = run(f.spec, cloth(), cloth_thickness());
    EXPECT_EQ(a.false_contacts + b.false_contacts, 0u);
    EXPECT_GE(a.recall(), f.folding);
    EXPECT_GE(b.recall(), f.cloth);
  }
}

// Every zone is examined within `every` frames: each zone's frames since its last examination,
// counted by the test from `zones()` frame by frame, stay below `every`.
TEST(Hybrid, EveryZoneExaminedWithinEveryFrames) {
  for (const int every : {1, 3, 5}) {
    SCOPED_TRACE(every);
    std::map<std::pair<Index, Index>, int> since;  // frames since examined, per zone
    std::size_t examined_total = 0, zone_frames = 0;
    run("hybrid:every=" + std::to_string(every), folding(), folding().thickness(), {}, [&](Detector& d, std::size_t i) {
      std::map<std::pair<Index, Index>, int> next;
      for (const ZoneInfo& z : as_hybrid(d).zones()) {
        const auto key = std::make_pair(z.leaf_a, z.leaf_b);
        const auto it = since.find(key);
        const int age = z.examined ? 0 : (it == since.end() ? 1 : it->second + 1);
        ASSERT_LT(age, every) << "zone " << z.leaf_a << "," << z.leaf_b << " frame " << i;
        EXPECT_EQ(age, z.age);
        next[key] = age;
        examined_total += z.examined ? 1 : 0;
        ++zone_frames;
      }
      EXPECT_EQ(d.stats().get("zones_due_left"), 0.0);
      EXPECT_LT(d.stats().get("oldest_zone_age"), every);
      since.swap(next);
    });
    if (every > 1) {
      EXPECT_LT(examined_total, zone_frames * 3 / 4) << "every > 1 examines fewer zones per frame";
    } else {
      EXPECT_EQ(examined_total, zone_frames);
    }
  }
}

// A budget counted in zones: exactly that many zones are examined per frame, the rest wait and
// come first next frame (oldest first), so every zone is examined within ceil(zones / cap) + 1
// frames. A time budget spent at once examines nothing and reports nothing.
TEST(Hybrid, BudgetStopsTheWorkAndResumesWhereItStopped) {
  const int cap = 7;
  std::map<std::pair<Index, Index>, int> since;
  std::size_t most_zones = 0;
  int oldest = 0;
  run("hybrid:zones=" + std::to_string(cap), folding(), folding().thickness(), {}, [&](Detector& d, std::size_t) {
    const auto zones = as_hybrid(d).zones();
    most_zones = std::max(most_zones, zones.size());
    std::size_t examined = 0;
    std::map<std::pair<Index, Index>, int> next;
    for (const ZoneInfo& z : zones) {
      examined += z.examined ? 1 : 0;
      const auto key = std::make_pair(z.leaf_a, z.leaf_b);
      const auto it = since.find(key);
      next[key] = z.examined ? 0 : (it == since.end() ? 1 : it->second + 1);
      oldest = std::max(oldest, next[key]);
    }
    EXPECT_EQ(examined, std::min<std::size_t>(cap, zones.size()));
    EXPECT_EQ(d.stats().get("zones_examined"), static_cast<double>(examined));
    since.swap(next);
  });
  EXPECT_GT(most_zones, static_cast<std::size_t>(3 * cap)) << "the cap must bite";
  EXPECT_LE(oldest, static_cast<int>((most_zones + cap - 1) / cap) + 1);

  // A time budget spent before the first zone.
  run("hybrid:budget=0.000001", folding(), folding().thickness(), {}, [&](Detector& d, std::size_t) {
    EXPECT_EQ(d.stats().get("zones_examined"), 0.0);
    EXPECT_EQ(d.stats().get("drawn"), 0.0);
  });
  // A budget far above the frame's cost changes nothing.
  auto free = make("hybrid", folding().thickness());
  auto generous = make("hybrid:budget=100000", folding().thickness());
  free->set_topology(folding().mesh().topology_ptr());
  generous->set_topology(folding().mesh().topology_ptr());
  ContactSet a, b;
  for (std::size_t i = 0; i < folding().size(); ++i) {
    free->update(folding().positions(i), a);
    generous->update(folding().positions(i), b);
    ASSERT_EQ(match_contacts(b, a).missed + match_contacts(b, a).false_contacts, 0u) << i;
  }
}

// A time budget is kept within a generous bound, on a sheet whose unbudgeted frames cost many
// times the budget (the budget bites: zones are left unexamined). The processor time of the
// median frame stays within twice the budget: the search stops at the first check past the
// deadline, at most one walk or zone row later, and the fixed costs (refit, zones, kept pairs)
// are a small part of it. Wall-clock time, which the deadline counts, also holds the time a
// loaded machine gives to other processes (a frame preempted near its deadline resumes a
// scheduler slice or more later: 40 ms medians were seen with a 4 ms budget at load 16 on 2
// cores), so it is only held to a loose bound; the processor-time bound is the check (the
// unbudgeted median is 3x it). Contacts stay true.
TEST(Hybrid, TimeBudgetKeptWithinAGenerousBound) {
#ifdef CRUMPLE_SANITIZED
  const FoldingSequence seq({.n = 40, .frames = 6, .seed = 2});
#else
  const FoldingSequence seq({.n = 48, .frames = 10, .seed = 2});
#endif
  constexpr double kBudgetMs = 10, kWallMarginMs = 200;
  // The reference: exact, and fast enough on this sheet; one thread, gone before the timing.
  const ReferenceRun ref = run_reference(
      *make_detector(MethodSpec::parse("kdop"), {.thickness = seq.thickness(), .threads = 1}), seq);
  auto d = make("hybrid:budget=" + std::to_string(kBudgetMs), seq.thickness());
  d->set_topology(seq.mesh().topology_ptr());
  std::vector<double> wall, cpu;
  std::size_t bitten = 0, found = 0;
  ContactSet got;
  Positions previous;
  for (std::size_t i = 0; i < seq.size(); ++i) {
    const Positions x = seq.positions(i);
    const std::clock_t cpu_start = std::clock();
    const auto start = std::chrono::steady_clock::now();
    d->update(previous.empty() ? PositionsView{} : PositionsView(previous), x, got);
    wall.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count());
    cpu.push_back(1000.0 * static_cast<double>(std::clock() - cpu_start) / CLOCKS_PER_SEC);
    expect_true_contacts(got, ref.contacts[i], i);
    found += got.size();
    bitten += d->stats().get("zones_examined") < d->stats().get("zones") ? 1 : 0;
    previous = x;
  }
  EXPECT_GE(bitten, seq.size() / 2) << "the budget must bite on most frames";
  EXPECT_GT(found, 0u) << "a budget that bites still finds contacts";
  std::sort(wall.begin(), wall.end());
  std::sort(cpu.begin(), cpu.end());
  EXPECT_LE(cpu[cpu.size() / 2], 2 * kBudgetMs);
  EXPECT_LE(wall[wall.size() / 2], kBudgetMs + kWallMarginMs);
}

TEST(Hybrid, SavedStateReplaysTheLastUpdateAndContinuesIdentically) {
  const FoldingSequence& seq = folding();
  for (const char* spec : {"hybrid", "hybrid:every=3,seed=4", "hybrid:zones=5"}) {
    SCOPED_TRACE(spec);
    auto a = make(spec, seq.thickness());
    a->set_topology(seq.mesh().topology_ptr());
    ContactSet ca, cb;
    const std::size_t k = seq.size() * 2 / 3;
    for (std::size_t i = 0; i <= k; ++i) {
      if (i == 0) {
        a->update(seq.positions(i), ca);
      } else {
        a->update(seq.positions(i - 1), seq.positions(i), ca);
      }
    }
    const std::string state = a->save_state();
    ASSERT_EQ(state.find('\n'), std::string::npos);
    EXPECT_NE(state.find(" kept "), std::string::npos);
    auto b = make(spec, seq.thickness());
    b->set_topology(seq.mesh().topology_ptr());
    b->load_state(state);
    b->update(seq.positions(k - 1), seq.positions(k), cb);  // replays a's last update
    ASSERT_EQ(match_contacts(cb, ca).missed + match_contacts(cb, ca).false_contacts, 0u);
    EXPECT_EQ(b->save_state(), state);
    for (std::size_t i = k + 1; i < seq.size(); ++i) {
      a->update(seq.positions(i - 1), seq.positions(i), ca);
      b->update(seq.positions(i - 1), seq.positions(i), cb);
      ASSERT_EQ(ca.size(), cb.size()) << "frame " << i;
      ASSERT_EQ(match_contacts(cb, ca).missed, 0u) << "frame " << i;
      for (const auto& [key, value] : a->stats().items()) {
        if (!key.ends_with("_ms")) {
          ASSERT_EQ(b->stats().get(key), value) << key << ", frame " << i;
        }
      }
    }
    // States that do not fit are refused.
    auto other = make("hybrid:seed=99", seq.thickness());
    other->set_topology(seq.mesh().topology_ptr());
    EXPECT_THROW(other->load_state(state), InputError);
    EXPECT_THROW(b->load_state("hybrid-state-1 nonsense"), InputError);
    const TriMesh tiny = shapes::lattice(2, 2, 1, 1);
    auto small = make(spec, seq.thickness());
    small->set_topology(tiny.topology_ptr());
    EXPECT_THROW(small->load_state(state), InputError);
    EXPECT_NO_THROW(small->load_state(""));
  }
}

TEST(Hybrid, DegenerateInputs) {
  // Two separate triangles, one vertex hovering over the other: found by both searches (the
  // stochastic one draws a single pair per frame here, so within a few frames; it keeps it).
  const TriMesh two = TriMesh::create({Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0), Vec3(0.25, 0.25, 0.05),
                                       Vec3(2, 2, 1), Vec3(2, 3, 1)},
                                      {{0, 1, 2}, {3, 4, 5}});
  ContactSet got;
  for (const char* spec : {"hybrid", "hybrid:search=exact", "hybrid:leaf=4,every=2"}) {
    auto d = make(spec, 0.1);
    d->set_topology(two.topology_ptr());
    for (int i = 0; i < 8; ++i) d->update(two.positions(), got);
    ASSERT_EQ(got.vf.size(), 1u) << spec;
    EXPECT_EQ(got.vf[0].vertex, 3);
    EXPECT_EQ(got.vf[0].face, 0);
    EXPECT_EQ(as_hybrid(*d).num_leaves(), 2);
  }
  // Thickness 0: nothing is in contact.
  auto zero = make("hybrid", 0);
  zero->set_topology(folding().mesh().topology_ptr());
  zero->update(folding().positions(folding().size() - 1), got);
  EXPECT_TRUE(got.empty());
}

TEST(Hybrid, DeterministicForASeed) {
  const FoldingSequence& seq = folding();
  auto a = make("hybrid:seed=3", seq.thickness());
  auto b = make("hybrid:seed=3", seq.thickness());
  a->set_topology(seq.mesh().topology_ptr());
  b->set_topology(seq.mesh().topology_ptr());
  ContactSet ca, cb;
  for (std::size_t i = 0; i < seq.size(); ++i) {
    a->update(seq.positions(i), ca);
    b->update(seq.positions(i), cb);
    ASSERT_EQ(ca.size(), cb.size());
    ASSERT_EQ(match_contacts(ca, cb).missed, 0u);
    ASSERT_EQ(a->stats().get("distance_evals"), b->stats().get("distance_evals"));
  }
}

}  // namespace
}  // namespace crumple
