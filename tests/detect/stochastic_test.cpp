// The stochastic detector (thesis Algorithms 2-3, every variant) against the exact reference on
// seeded deforming sequences: recall floors (measured, then set below the measured value),
// no false contact ever, determinism, and the invariants of the kept pairs after each update.
//
// Sequence: `FoldingSequence` (detect/compare.hpp) — a lattice folded over itself whose upper
// layer tilts through the lower one with a travelling ripple, seeded; thickness ℓ/4. It stands
// in for the simulation scenes until the simulator exists.
#include <crumple/core/error.hpp>
#include <crumple/detect/compare.hpp>
#include <crumple/detect/detector.hpp>
#include <crumple/detect/stochastic.hpp>
#include <crumple/geometry/distance.hpp>
#include <crumple/geometry/triangle_intersection.hpp>
#include <crumple/mesh/shapes.hpp>
#include <support/meshes.hpp>
#include <support/run_cache.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <set>
#include <sstream>
#include <tuple>

namespace crumple {
namespace {

const char* const kVariants[] = {"simple", "propagate-by-convergence", "direct", "vertex"};

std::unique_ptr<Detector> make(const std::string& spec, Scalar h, ContactKinds kinds = {}) {
  return make_detector(MethodSpec::parse(spec), {.thickness = h, .kinds = kinds});
}

/// The test sequence (small enough for the O(n²) reference under sanitizers).
const FoldingSequence& sequence() {
  static const FoldingSequence s({.n = 16, .frames = 40, .seed = 7});
  return s;
}

/// Reference contacts of `sequence()`, computed once per build of this program
/// (support/run_cache.hpp: most tests here need them, and each runs in a process of its own).
const ReferenceRun& reference_run() {
  static const ReferenceRun run = testing::cached_naive_reference(sequence(), sequence().thickness());
  return run;
}

/// Every reported contact is in the reference with identical fields (same narrow phase); the
/// set is sorted without duplicates and holds no adjacent pair.
void expect_true_contacts(const Topology& topo, const ContactSet& got, const ContactSet& ref) {
  std::map<std::pair<Index, Index>, const VertexFaceContact*> vf;
  for (const auto& c : ref.vf) vf[{c.vertex, c.face}] = &c;
  std::map<std::pair<Edge, Edge>, const EdgeEdgeContact*> ee;
  for (const auto& c : ref.ee) ee[{c.a, c.b}] = &c;
  std::set<std::pair<Index, Index>> tt;
  for (const auto& c : ref.tt) tt.insert({c.face0, c.face1});
  for (std::size_t i = 0; i < got.vf.size(); ++i) {
    const auto& c = got.vf[i];
    if (i > 0) {
      ASSERT_LT(std::tie(got.vf[i - 1].vertex, got.vf[i - 1].face), std::tie(c.vertex, c.face));
    }
    ASSERT_FALSE(topo.face_has_vertex(c.face, c.vertex));
    const auto it = vf.find({c.vertex, c.face});
    ASSERT_NE(it, vf.end()) << "false VF contact " << c.vertex << " " << c.face;
    EXPECT_EQ(c.distance, it->second->distance);
    EXPECT_EQ(c.barycentric, it->second->barycentric);
    EXPECT_EQ(c.normal, it->second->normal);
  }
  for (std::size_t i = 0; i < got.ee.size(); ++i) {
    const auto& c = got.ee[i];
    if (i > 0) {
      ASSERT_LT(std::tie(got.ee[i - 1].a, got.ee[i - 1].b), std::tie(c.a, c.b));
    }
    ASSERT_FALSE(topo.edges_adjacent(c.edge0, c.edge1));
    const auto it = ee.find({c.a, c.b});
    ASSERT_NE(it, ee.end()) << "false EE contact";
    EXPECT_EQ(c.distance, it->second->distance);
    EXPECT_EQ(c.s, it->second->s);
    EXPECT_EQ(c.t, it->second->t);
    EXPECT_EQ(c.normal, it->second->normal);
    EXPECT_EQ(c.edge0, it->second->edge0);
  }
  for (std::size_t i = 0; i < got.tt.size(); ++i) {
    const auto& c = got.tt[i];
    if (i > 0) {
      ASSERT_LT(std::tie(got.tt[i - 1].face0, got.tt[i - 1].face1), std::tie(c.face0, c.face1));
    }
    ASSERT_FALSE(topo.faces_adjacent(c.face0, c.face1));
    ASSERT_TRUE(tt.count({c.face0, c.face1})) << "false TT contact";
  }
}

// --- Independent re-implementation of the pair graph, for the invariants -------------------

const Vec3& X(PositionsView x, Index i) { return x[static_cast<std::size_t>(i)]; }

bool excluded(const Topology& t, PairType type, Index a, Index b) {
  switch (type) {
    case PairType::VV: {
      const auto ring = t.vertex_vertices()[a];
      return a == b || std::find(ring.begin(), ring.end(), b) != ring.end();
    }
    case PairType::EE: return t.edges_adjacent(a, b);
    case PairType::VF: return t.face_has_vertex(b, a);
    case PairType::EF: {
      const Edge& e = t.edge(a);
      return t.face_has_vertex(b, e[0]) || t.face_has_vertex(b, e[1]);
    }
  }
  return true;
}

/// The convergence metric: L1 for VV, squared Euclidean otherwise.
Scalar metric(const Topology& t, PositionsView x, PairType type, Index a, Index b) {
  switch (type) {
    case PairType::VV: return (X(x, a) - X(x, b)).cwiseAbs().sum();
    case PairType::EE: {
      if (b < a) std::swap(a, b);
      const Edge &p = t.edge(a), &q = t.edge(b);
      return geometry::segment_segment(X(x, p[0]), X(x, p[1]), X(x, q[0]), X(x, q[1])).sqr_distance;
    }
    case PairType::VF: {
      const Face& f = t.face(b);
      return geometry::point_triangle(X(x, a), X(x, f[0]), X(x, f[1]), X(x, f[2])).sqr_distance;
    }
    case PairType::EF: {
      const Edge& e = t.edge(a);
      const Face& f = t.face(b);
      if (geometry::segment_triangle_intersect(X(x, e[0]), X(x, e[1]), X(x, f[0]), X(x, f[1]), X(x, f[2]))) return 0;
      Scalar d = std::min(geometry::point_triangle(X(x, e[0]), X(x, f[0]), X(x, f[1]), X(x, f[2])).sqr_distance,
                          geometry::point_triangle(X(x, e[1]), X(x, f[0]), X(x, f[1]), X(x, f[2])).sqr_distance);
      for (int k = 0; k < 3; ++k) {
        d = std::min(d, geometry::segment_segment(X(x, e[0]), X(x, e[1]), X(x, f[k]), X(x, f[(k + 1) % 3])).sqr_distance);
      }
      return d;
    }
  }
  return 0;
}

std::span<const Index> neighbours(const Topology& t, PairType type, bool first, Index i) {
  switch (type) {
    case PairType::VV: return t.vertex_vertices()[i];
    case PairType::EE: return t.edge_edges()[i];
    case PairType::VF: return first ? t.vertex_vertices()[i] : t.face_faces()[i];
    case PairType::EF: return first ? t.edge_edges()[i] : t.face_faces()[i];
  }
  return {};
}

/// Smallest Euclidean distance among the VF/EE sub-pairs of the faces around vertices a and b.
Scalar zone_distance(const Topology& t, PositionsView x, Index a, Index b) {
  Scalar best = std::numeric_limits<Scalar>::infinity();
  for (const Index fa : t.vertex_faces()[a]) {
    for (const Index fb : t.vertex_faces()[b]) {
      if (fa == fb) continue;
      for (int k = 0; k < 3; ++k) {
        if (!t.face_has_vertex(fb, t.face(fa)[k])) best = std::min(best, metric(t, x, PairType::VF, t.face(fa)[k], fb));
        if (!t.face_has_vertex(fa, t.face(fb)[k])) best = std::min(best, metric(t, x, PairType::VF, t.face(fb)[k], fa));
        for (int j = 0; j < 3; ++j) {
          const Index e0 = t.face_edges(fa)[k], e1 = t.face_edges(fb)[j];
          if (!t.edges_adjacent(e0, e1)) best = std::min(best, metric(t, x, PairType::EE, e0, e1));
        }
      }
    }
  }
  return std::sqrt(best);
}

/// Kept pairs: not adjacent, no duplicates, at most `active`, within the near distance, and
/// local minima of the metric over their neighbour pairs.
void expect_invariants(const StochasticDetector& d, PositionsView x) {
  const Topology& t = d.topology();
  const Scalar near = d.near_distance();
  for (const PairType type : {PairType::VV, PairType::EE, PairType::VF, PairType::EF}) {
    SCOPED_TRACE(std::string(to_string(type)));
    const auto kept = d.near_pairs(type);
    if (!d.runs(type)) {
      EXPECT_TRUE(kept.empty());
      continue;
    }
    EXPECT_LE(kept.size(), static_cast<std::size_t>(d.params().active));
    std::set<std::pair<Index, Index>> seen;
    for (const PrimitivePair& p : kept) {
      ASSERT_FALSE(excluded(t, type, p.a, p.b));
      if (type == PairType::VV || type == PairType::EE) {
        ASSERT_LT(p.a, p.b);
      }
      ASSERT_TRUE(seen.insert({p.a, p.b}).second) << "duplicate kept pair " << p.a << " " << p.b;
      const Scalar m = metric(t, x, type, p.a, p.b);
      if (type == PairType::VV) {
        EXPECT_LE(zone_distance(t, x, p.a, p.b), near);
      } else {
        EXPECT_LE(m, near * near);
      }
      for (const Index n : neighbours(t, type, true, p.a)) {
        if (!excluded(t, type, n, p.b)) {
          ASSERT_GE(metric(t, x, type, n, p.b), m) << "not a local minimum";
        }
      }
      for (const Index n : neighbours(t, type, false, p.b)) {
        if (!excluded(t, type, p.a, n)) {
          ASSERT_GE(metric(t, x, type, p.a, n), m) << "not a local minimum";
        }
      }
    }
    for (const PrimitivePair& p : d.colliding_pairs(type)) {
      ASSERT_FALSE(excluded(t, type, p.a, p.b));
      if (type != PairType::VV) {
        EXPECT_LT(metric(t, x, type, p.a, p.b), d.options().thickness * d.options().thickness);
      }
    }
  }
}

// --- Parameters ------------------------------------------------------------------------------

TEST(StochasticParams, DefaultsSettingsAndOverrides) {
  StochasticParams p = StochasticParams::from_spec(MethodSpec::parse("stochastic"));
  EXPECT_EQ(p.variant, StochasticVariant::Direct);
  EXPECT_EQ(p.propagation, Propagation::Linear);
  EXPECT_EQ(p.active, 100);
  EXPECT_EQ(p.draw, 100);
  EXPECT_EQ(p.near, 2.0);
  EXPECT_EQ(p.seed, 1u);
  p = StochasticParams::from_spec(MethodSpec::parse("stochastic:setting=1,variant=simple"));
  EXPECT_EQ(p.active, 10);
  EXPECT_EQ(p.draw, 10);
  EXPECT_EQ(p.propagation, Propagation::Full);
  p = StochasticParams::from_spec(MethodSpec::parse("stochastic:setting=2,variant=vertex"));
  EXPECT_EQ(p.active, 100);
  EXPECT_EQ(p.propagation, Propagation::None);
  p = StochasticParams::from_spec(
      MethodSpec::parse("stochastic:setting=2,propagation=full,active=7,draw=3,near=3.5,seed=42,steps=9,ef=on"));
  EXPECT_EQ(p.propagation, Propagation::Full);
  EXPECT_EQ(p.active, 7);
  EXPECT_EQ(p.draw, 3);
  EXPECT_EQ(p.near, 3.5);
  EXPECT_EQ(p.seed, 42u);
  EXPECT_EQ(p.steps, 9);
  EXPECT_TRUE(p.ef);
  EXPECT_EQ(StochasticParams::from_spec(MethodSpec::parse(p.to_string())).to_string(), p.to_string());
  for (const char* bad : {"stochastic:variant=bogus", "stochastic:active=0", "stochastic:near=0.5",
                          "stochastic:setting=3", "stochastic:draw=-1", "stochastic:steps=0",
                          "stochastic:propagation=half", "stochastic:seed=-2", "stochastic:active=x"}) {
    EXPECT_THROW(make(bad, 0.1), InputError) << bad;
  }
  EXPECT_TRUE(method_info(Method::Stochastic).capabilities.stochastic);
  EXPECT_FALSE(method_info(Method::Stochastic).capabilities.exact);
}

// --- Against the reference -------------------------------------------------------------------

/// Overall recall of a spec over `sequence()`; every frame is checked for false or altered
/// contacts and for the invariants of the kept pairs.
double measured_recall(const std::string& spec, ContactKinds kinds = {}) {
  auto d = make(spec, sequence().thickness(), kinds);
  auto& sto = dynamic_cast<StochasticDetector&>(*d);
  sto.set_topology(sequence().mesh().topology_ptr());
  const ReferenceRun& ref = reference_run();
  std::size_t found = 0, total = 0;
  ContactSet got;
  Positions previous;
  for (std::size_t i = 0; i < sequence().size(); ++i) {
    SCOPED_TRACE(spec + " frame " + std::to_string(i));
    const Positions x = sequence().positions(i);
    d->update(previous, x, got);
    ContactSet want = ref.contacts[i];
    if (!kinds.vf) want.vf.clear();
    if (!kinds.ee) want.ee.clear();
    expect_true_contacts(sequence().mesh().topology(), got, want);
    expect_invariants(sto, x);
    const ContactMatch m = match_contacts(got, want);
    EXPECT_EQ(m.false_contacts, 0u);
    found += m.found;
    total += m.reference;
    previous = x;
  }
  return total == 0 ? 1.0 : static_cast<double>(found) / static_cast<double>(total);
}

TEST(Stochastic, SequenceHasGrowingContact) {
  const ReferenceRun& ref = reference_run();
  EXPECT_TRUE(ref.contacts.front().empty());
  std::size_t total = 0;
  for (const auto& c : ref.contacts) total += c.size();
  EXPECT_GT(ref.contacts.back().size(), 100u);
  EXPECT_GT(total, 2000u);
}

// Recall over the 40-frame sequence (n = 16, seed 7, thickness ℓ/4), measured with this code
// for detector seeds 1..8 (`crumple compare --method stochastic:variant=V,setting=S,seed=K
// --size 16 --frames 40 --seed 7`):
//   variant                    setting 1      setting 2
//   simple                     0.856-0.945    0.320-0.335
//   propagate-by-convergence   0.882-0.965    0.320-0.335
//   direct                     0.928-0.969    0.844-0.870
//   vertex                     0.942-1.000    0.970-0.986
// The floors sit 3-4 points under the worst seed; they are asserted for seeds 1, 2 and 3.
// (Setting 2 of simple / propagate-by-convergence is not a thesis combination: without
// propagation or the direct side effect only one pair per local minimum is found.)
struct Floor {
  const char* variant;
  int setting;
  double floor;
};
constexpr Floor kFloors[] = {
    {"simple", 1, 0.82}, {"simple", 2, 0.29},
    {"propagate-by-convergence", 1, 0.85}, {"propagate-by-convergence", 2, 0.29},
    {"direct", 1, 0.89}, {"direct", 2, 0.81},
    {"vertex", 1, 0.91}, {"vertex", 2, 0.94},
};

TEST(Stochastic, RecallAboveMeasuredFloorsAndNoFalseContact) {
  for (const Floor& f : kFloors) {
    for (int seed : {1, 2, 3}) {
      const std::string spec = std::string("stochastic:variant=") + f.variant +
                               ",setting=" + std::to_string(f.setting) + ",seed=" + std::to_string(seed);
      const double recall = measured_recall(spec);
      std::printf("%-60s recall %.4f (floor %.2f)\n", spec.c_str(), recall, f.floor);
      EXPECT_GE(recall, f.floor) << spec;
    }
  }
}

TEST(Stochastic, EveryPropagationModeAndVariantNeverReportsFalseContacts) {
  for (const char* variant : kVariants) {
    for (const char* prop : {"none", "linear", "full"}) {
      const std::string spec = std::string("stochastic:variant=") + variant + ",propagation=" + prop + ",active=20";
      const double recall = measured_recall(spec);
      std::printf("%-55s recall %.4f\n", spec.c_str(), recall);
      EXPECT_GT(recall, 0.05) << spec;
    }
  }
}


TEST(Stochastic, RespectsContactKinds) {
  const ContactKinds ee_only = ContactKinds::parse("ee");
  const ContactKinds vf_only = ContactKinds::parse("vf");
  for (const char* variant : {"direct", "vertex"}) {
    const std::string spec = std::string("stochastic:setting=1,variant=") + variant;
    EXPECT_GT(measured_recall(spec, ee_only), 0.5) << spec;
    EXPECT_GT(measured_recall(spec, vf_only), 0.5) << spec;
  }
  auto d = make("stochastic", 0.1, ee_only);
  auto& sto = dynamic_cast<StochasticDetector&>(*d);
  EXPECT_TRUE(sto.runs(PairType::EE));
  EXPECT_FALSE(sto.runs(PairType::VF));
  EXPECT_FALSE(sto.runs(PairType::EF));
  EXPECT_FALSE(sto.runs(PairType::VV));
}

TEST(Stochastic, EdgeFacePairsAndTriangleIntersections) {
  // EF on top of VF/EE: still only true contacts, kept EF pairs are local minima.
  EXPECT_GT(measured_recall("stochastic:setting=1,ef=on"), 0.85);
  // TT through the EF pair type (and face pairs of the vertex variant) on the last frames.
  const ContactKinds tt = ContactKinds::parse("tt");
  const Scalar h = sequence().thickness();
  auto naive = make("naive", h, tt);
  naive->set_topology(sequence().mesh().topology_ptr());
  for (const char* spec : {"stochastic:setting=1", "stochastic:setting=1,variant=vertex"}) {
    auto d = make(spec, h, tt);
    d->set_topology(sequence().mesh().topology_ptr());
    EXPECT_TRUE(dynamic_cast<StochasticDetector&>(*d).runs(std::string(spec).find("vertex") != std::string::npos ? PairType::VV : PairType::EF));
    std::size_t found = 0, total = 0;
    ContactSet got, want;
    for (std::size_t i = 0; i < sequence().size(); ++i) {
      const Positions x = sequence().positions(i);
      d->update(x, got);
      if (i + 8 < sequence().size()) continue;
      naive->update(x, want);
      SCOPED_TRACE(std::string(spec) + " frame " + std::to_string(i));
      EXPECT_TRUE(got.vf.empty() && got.ee.empty());
      expect_true_contacts(sequence().mesh().topology(), got, want);
      const ContactMatch m = match_contacts(got, want);
      found += m.found;
      total += m.reference;
    }
    std::printf("%s tt recall %zu / %zu\n", spec, found, total);
    EXPECT_GT(total, 0u);
    EXPECT_GT(found, total / 2) << spec;
  }
}

TEST(Stochastic, DeterministicForASeedAndResetBySetTopology) {
  const Scalar h = sequence().thickness();
  for (const char* variant : kVariants) {
    const std::string spec = std::string("stochastic:variant=") + variant + ",active=15";
    auto a = make(spec, h), b = make(spec, h), c = make(spec + ",seed=99", h);
    a->set_topology(sequence().mesh().topology_ptr());
    b->set_topology(sequence().mesh().topology_ptr());
    c->set_topology(sequence().mesh().topology_ptr());
    std::vector<ContactSet> first;
    bool seed_matters = false;
    ContactSet ca, cb, cc;
    for (std::size_t i = 0; i < 20; ++i) {
      const Positions x = sequence().positions(i + 20);
      a->update(x, ca);
      b->update(x, cb);
      c->update(x, cc);
      std::ostringstream sa, sb;
      write_contacts(sa, ca);
      write_contacts(sb, cb);
      ASSERT_EQ(sa.str(), sb.str()) << spec << " frame " << i;
      ASSERT_EQ(a->stats().items(), b->stats().items()) << spec << " frame " << i;
      seed_matters |= a->stats().items() != c->stats().items();
      first.push_back(ca);
    }
    EXPECT_TRUE(seed_matters) << spec;
    // A new topology starts over: the same frames give the same results again.
    a->set_topology(sequence().mesh().topology_ptr());
    for (std::size_t i = 0; i < 20; ++i) {
      a->update(sequence().positions(i + 20), ca);
      std::ostringstream s0, s1;
      write_contacts(s0, first[i]);
      write_contacts(s1, ca);
      ASSERT_EQ(s0.str(), s1.str()) << spec << " frame " << i << " after set_topology";
    }
  }
}

TEST(Stochastic, FrozenConfigurationIsFullyFoundWithinAFewFrames) {
  // ALGORITHMS.md §1: on a frozen configuration recall reaches 1 within a few steps with high
  // probability. Last frame of the sequence (~280 contacts in several patches) repeated up to
  // 20 times, 10 seeds, 100 active pairs with full propagation. Measured: direct and vertex
  // complete for 20/20 seeds; simple and propagate-by-convergence for about half of the seeds,
  // the others miss one contact (an isolated pair that is neither a local minimum nor next to
  // another colliding pair: only the direct side effect or the vertex zones catch it).
  const Scalar h = sequence().thickness();
  const Positions x = sequence().positions(sequence().size() - 1);
  const ContactSet& want = reference_run().contacts.back();
  ASSERT_GT(want.size(), 100u);
  for (const char* variant : kVariants) {
    int complete = 0;
    double worst = 1;
    for (int seed = 1; seed <= 10; ++seed) {
      auto d = make(std::string("stochastic:propagation=full,active=100,variant=") + variant +
                        ",seed=" + std::to_string(seed), h);
      d->set_topology(sequence().mesh().topology_ptr());
      ContactSet got;
      double recall = 0;
      for (int frame = 0; frame < 20 && recall < 1; ++frame) {
        d->update(x, got);
        recall = match_contacts(got, want).recall();
      }
      complete += recall == 1.0;
      worst = std::min(worst, recall);
    }
    std::printf("%s: complete within 20 frozen frames for %d / 10 seeds, worst recall %.4f\n", variant,
                complete, worst);
    EXPECT_GE(worst, 0.99) << variant;
    if (variant == std::string("direct") || variant == std::string("vertex")) {
      EXPECT_GE(complete, 9) << variant;
    }
  }
}

TEST(Stochastic, StatisticsAreConsistent) {
  const Scalar h = sequence().thickness();
  for (const char* variant : kVariants) {
    auto d = make(std::string("stochastic:setting=1,ef=on,variant=") + variant, h);
    auto& sto = dynamic_cast<StochasticDetector&>(*d);
    d->set_topology(sequence().mesh().topology_ptr());
    ContactSet got;
    for (std::size_t i = 25; i < 35; ++i) {
      d->update(sequence().positions(i), got);
      const DetectorStats& s = d->stats();
      double kept = 0, drawn = 0, evals = 0;
      for (const PairType t : {PairType::VV, PairType::EE, PairType::VF, PairType::EF}) {
        const std::string p = std::string(to_string(t)) + "_";
        if (!sto.runs(t)) {
          EXPECT_EQ(s.get(p + "drawn"), 0);
          continue;
        }
        EXPECT_EQ(s.get(p + "kept"), static_cast<double>(sto.near_pairs(t).size()));
        EXPECT_EQ(s.get(p + "colliding"), static_cast<double>(sto.colliding_pairs(t).size()));
        EXPECT_LE(s.get(p + "drawn"), sto.params().draw);
        EXPECT_LE(s.get(p + "kept"), sto.params().active);
        EXPECT_LE(s.get(p + "duplicates"), s.get(p + "deleted"));
        kept += s.get(p + "kept");
        drawn += s.get(p + "drawn");
        evals += s.get(p + "distance_evals");
      }
      EXPECT_EQ(s.get("kept"), kept);
      EXPECT_EQ(s.get("drawn"), drawn);
      EXPECT_EQ(s.get("distance_evals"), evals);
      EXPECT_GT(evals, 0);
      if (variant == std::string("direct") || variant == std::string("vertex")) {
        EXPECT_GT(s.get("cache_hits"), 0);
      }
      EXPECT_GT(s.get("propagation_visits"), 0) << variant;
    }
  }
}

TEST(Stochastic, CostPerFrameDoesNotGrowWithMeshSize) {
  // Fixed parameters, no propagation: distance evaluations per frame are bounded by the
  // parameters, not by the mesh. On a small mesh walks end before the `steps` cap, so a frame
  // costs less; from 48x48 on, walks from random pairs are longer than the cap and carry on
  // next frame, and the cost is flat (48x48 to 192x192: 16 times more elements).
  const auto mean_evals = [](Index n, const std::string& extra) {
    const FoldingSequence seq({.n = n, .frames = 12, .seed = 3});
    auto d = make("stochastic:setting=2,variant=direct" + extra, seq.thickness());
    d->set_topology(seq.mesh().topology_ptr());
    ContactSet got;
    double sum = 0, walking = 0;
    for (std::size_t i = 0; i < seq.size(); ++i) {
      d->update(seq.positions(i), got);
      sum += d->stats().get("distance_evals");
      walking += d->stats().get("walking");
    }
    if (n >= 48) {
      EXPECT_GT(walking, 0) << n << ": walks should outlast the cap on a large mesh";
    }
    return sum / static_cast<double>(seq.size());
  };
  const double small = mean_evals(12, ""), mid = mean_evals(48, ""), big = mean_evals(96, ""),
               large = mean_evals(192, "");
  std::printf("distance evaluations per frame: 12x12 %.0f, 48x48 %.0f, 96x96 %.0f, 192x192 %.0f\n", small, mid,
              big, large);
  EXPECT_LT(std::max({mid, big, large}), 1.3 * std::min({mid, big, large}));
  const auto p = StochasticParams::from_spec(MethodSpec::parse("stochastic:setting=2"));
  // Each of the two pair types: at most (active + draw) walks of at most `steps` moves over
  // neighbour pairs (degree <= 2 * 14 on a lattice), plus one evaluation per start.
  for (const double evals : {small, mid, big, large}) {
    EXPECT_LT(evals, 2.0 * (p.active + p.draw) * (p.steps * 28 + 1));
  }
  // With the walks cut short the cost is set by `steps`: four times the steps, about four
  // times the cost on the large mesh.
  const double long_walks = mean_evals(192, ",steps=64");
  std::printf("192x192 with steps=64: %.0f\n", long_walks);
  EXPECT_GT(long_walks, 2.0 * large);
}

TEST(Stochastic, UnfinishedWalksCarryOverToTheNextFrame) {
  // One edge-edge walk of at most 2 moves per frame on a large crumpled sheet: a walk that is
  // not over goes on next frame from where it stopped (distance still falling, nothing drawn)
  // until it reaches a minimum, instead of being dropped and redrawn.
  const FoldingSequence seq({.n = 64, .frames = 8, .seed = 2});
  const Positions x = seq.positions(seq.size() - 1);
  const Topology& topo = seq.mesh().topology();
  auto d = make("stochastic:variant=simple,active=1,draw=1,steps=2,propagation=none", seq.thickness(),
                ContactKinds::parse("ee"));
  auto& sto = dynamic_cast<StochasticDetector&>(*d);
  d->set_topology(seq.mesh().topology_ptr());
  const auto sqr = [&](PrimitivePair p) {
    const Edge& a = topo.edge(p.a);
    const Edge& b = topo.edge(p.b);
    return geometry::segment_segment(x[static_cast<std::size_t>(a[0])], x[static_cast<std::size_t>(a[1])],
                                     x[static_cast<std::size_t>(b[0])], x[static_cast<std::size_t>(b[1])])
        .sqr_distance;
  };
  ContactSet got;
  int carried = 0, finished_after_carry = 0, longest = 0, run = 0;
  std::vector<PrimitivePair> walking;
  for (int frame = 0; frame < 300; ++frame) {
    d->update(x, got);
    const DetectorStats& s = d->stats();
    const auto now = sto.walking_pairs(PairType::EE);
    ASSERT_LE(now.size() + sto.near_pairs(PairType::EE).size(), 1u);
    ASSERT_LE(s.get("converge_steps"), 2.0 * (1 + s.get("drawn")));
    if (!walking.empty()) {
      ++carried;
      if (s.get("drawn") == 0 && !now.empty()) {
        ASSERT_LT(sqr(now[0]), sqr(walking[0])) << "frame " << frame << ": the walk went on downhill";
      } else {
        // The walk ended at a minimum this frame: kept if near, else deleted and redrawn.
        ASSERT_EQ(s.get("deleted") + static_cast<double>(sto.near_pairs(PairType::EE).size()), 1.0)
            << "frame " << frame;
        ++finished_after_carry;
      }
    }
    run = now.empty() ? 0 : run + 1;
    longest = std::max(longest, run);
    walking.assign(now.begin(), now.end());
  }
  EXPECT_GT(carried, 20);
  std::printf("carried %d, finished after a carry %d, longest %d frames\n", carried, finished_after_carry, longest);
  EXPECT_GE(finished_after_carry, 1);
  EXPECT_GE(longest, 3) << "some walk should take more than three frames";
}

TEST(Stochastic, DegenerateInputs) {
  // One triangle: every pair is adjacent, draws are all rejected; no contact, no crash.
  const TriMesh one = TriMesh::create({Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0)}, {{0, 1, 2}});
  for (const char* variant : kVariants) {
    auto d = make(std::string("stochastic:ef=on,variant=") + variant, 0.5, ContactKinds::parse("vf,ee,tt"));
    d->set_topology(one.topology_ptr());
    ContactSet got;
    d->update(one.positions(), got);
    EXPECT_TRUE(got.empty());
  }
  // Thickness 0: no proximity contact at all.
  auto d = make("stochastic:setting=1", 0.0);
  d->set_topology(sequence().mesh().topology_ptr());
  ContactSet got;
  d->update(sequence().positions(sequence().size() - 1), got);
  EXPECT_TRUE(got.empty());
  // Two separate triangles, one vertex hovering over the other: found in one frame (few pairs).
  const TriMesh two = TriMesh::create({Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0), Vec3(0.25, 0.25, 0.05),
                                       Vec3(2, 2, 1), Vec3(2, 3, 1)},
                                      {{0, 1, 2}, {3, 4, 5}});
  for (const char* variant : kVariants) {
    auto s = make(std::string("stochastic:active=50,variant=") + variant, 0.1);
    s->set_topology(two.topology_ptr());
    s->update(two.positions(), got);
    ASSERT_EQ(got.vf.size(), 1u) << variant;
    EXPECT_EQ(got.vf[0].vertex, 3);
    EXPECT_EQ(got.vf[0].face, 0);
  }
}

TEST(Stochastic, SavedStateReplaysTheLastUpdateAndContinuesIdentically) {
  const FoldingSequence& seq = sequence();
  for (const char* variant : kVariants) {
    SCOPED_TRACE(variant);
    const std::string spec = std::string("stochastic:active=30,variant=") + variant;
    auto a = make(spec, seq.thickness());
    a->set_topology(seq.mesh().topology_ptr());
    ContactSet ca, cb;
    const std::size_t k = 25;
    for (std::size_t i = 0; i <= k; ++i) a->update(seq.positions(i), ca);
    const std::string state = a->save_state();
    ASSERT_EQ(state.find('\n'), std::string::npos) << "one line";
    auto b = make(spec, seq.thickness());
    b->set_topology(seq.mesh().topology_ptr());
    b->load_state(state);
    b->update(seq.positions(k), cb);  // replays a's last update
    ASSERT_EQ(match_contacts(cb, ca).missed + match_contacts(cb, ca).false_contacts, 0u);
    EXPECT_EQ(b->save_state(), state);
    for (std::size_t i = k + 1; i < seq.size(); ++i) {
      a->update(seq.positions(i), ca);
      b->update(seq.positions(i), cb);
      ASSERT_EQ(ca.size(), cb.size()) << "frame " << i;
      ASSERT_EQ(match_contacts(cb, ca).missed, 0u) << "frame " << i;
    }
    // A state that does not fit is refused with a clear message.
    auto other = make("stochastic:active=31", seq.thickness());
    other->set_topology(seq.mesh().topology_ptr());
    EXPECT_THROW(other->load_state(state), InputError);
    EXPECT_THROW(b->load_state("stochastic-state-2 nonsense"), InputError);
    const TriMesh tiny = shapes::lattice(2, 2, 1, 1);
    auto small = make(spec, seq.thickness());
    small->set_topology(tiny.topology_ptr());
    if (state.find(" ee 0 ") == std::string::npos || state.find(" vv 0 ") == std::string::npos) {
      EXPECT_THROW(small->load_state(state), InputError) << "pairs out of range for a smaller mesh";
    }
    EXPECT_NO_THROW(small->load_state(""));
  }
  auto naive = make("naive", 0.1);
  naive->set_topology(sequence().mesh().topology_ptr());
  EXPECT_EQ(naive->save_state(), "");
  EXPECT_NO_THROW(naive->load_state(""));
  EXPECT_THROW(naive->load_state("stochastic-state-2 x"), InputError);
}

TEST(Stochastic, TimeBudget) {
  // Parsing: the key, its range and the canonical text.
  EXPECT_EQ(StochasticParams::from_spec(MethodSpec::parse("stochastic")).budget_ms, 0.0);
  const StochasticParams p = StochasticParams::from_spec(MethodSpec::parse("stochastic:budget=2.5"));
  EXPECT_EQ(p.budget_ms, 2.5);
  EXPECT_NE(p.to_string().find(",budget=2.5"), std::string::npos) << p.to_string();
  EXPECT_EQ(StochasticParams::from_spec(MethodSpec::parse(p.to_string())).budget_ms, 2.5);
  EXPECT_THROW(StochasticParams::from_spec(MethodSpec::parse("stochastic:budget=-1")), InputError);
  EXPECT_THROW(StochasticParams::from_spec(MethodSpec::parse("stochastic:budget=inf")), InputError);

  const FoldingSequence& seq = sequence();
  const ReferenceRun& ref = reference_run();
  for (const char* variant : kVariants) {
    SCOPED_TRACE(variant);
    // A budget far above the frame's cost changes nothing: same contacts as without one.
    auto free = make(std::string("stochastic:variant=") + variant, seq.thickness());
    auto generous = make(std::string("stochastic:budget=100000,variant=") + variant, seq.thickness());
    // A budget spent before the first draw: nothing is drawn, nothing is found, never a false
    // contact.
    auto spent = make(std::string("stochastic:budget=0.000001,variant=") + variant, seq.thickness());
    for (auto* d : {free.get(), generous.get(), spent.get()}) d->set_topology(seq.mesh().topology_ptr());
    ContactSet a, b, c;
    for (std::size_t i = 0; i < seq.size(); ++i) {
      const Positions x = seq.positions(i);
      free->update(x, a);
      generous->update(x, b);
      spent->update(x, c);
      ASSERT_EQ(match_contacts(b, a).missed, 0u) << "frame " << i;
      ASSERT_EQ(match_contacts(b, a).false_contacts, 0u) << "frame " << i;
      EXPECT_EQ(spent->stats().get("drawn"), 0.0) << "frame " << i;
      EXPECT_EQ(spent->stats().get("propagation_visits"), 0.0) << "frame " << i;
      EXPECT_TRUE(c.empty()) << "frame " << i;
      EXPECT_EQ(match_contacts(c, ref.contacts[i]).false_contacts, 0u);
    }
    EXPECT_GT(a.size(), 0u) << "the last frame has contacts to find";
  }
}

}  // namespace
}  // namespace crumple
