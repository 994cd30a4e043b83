// `kdop` cut off by a budget (exact_detector.hpp, "Cut-off frames"): the naive way to keep a
// time budget with an exact method, the baseline of the hybrid's benchmark (docs/hybrid.md).
// Counted in work, not time: with `pairs=N` the frame narrow-tests exactly N candidates when it
// has more (stat `pairs_tested`), returns a subset of the full set with every field the same
// bits, in canonical order, the same for the same frames, growing with N, and the full set
// when N covers the candidates; with `track`, no repeats, more found at the same N, and the
// full set reached on a still frame. A time budget is checked at its two ends only (spent before the
// first claim: nothing; never spent: everything). A traversal stopped on a refresh frame of the
// frame-to-frame cache must not leave an incomplete cache behind. Streamed finely (a cut-off
// frame), the traversal stops inside a task: candidates handed over a few dozen at a time, and
// the consumer's poll asked between them.
#include <crumple/core/error.hpp>
#include <crumple/detect/broad_phase/kdop_tree.hpp>
#include <crumple/detect/compare.hpp>
#include <crumple/detect/detector.hpp>
#include <crumple/detect/exact_detector.hpp>
#include <crumple/mesh/shapes.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <functional>
#include <map>
#include <set>
#include <string>
#include <vector>

namespace crumple {
namespace {

const FoldingSequence& folding() {
#ifdef CRUMPLE_SANITIZED
  static const FoldingSequence s({.n = 16, .frames = 16, .seed = 7});
#else
  static const FoldingSequence s({.n = 16, .frames = 40, .seed = 7});
#endif
  return s;
}

/// Runs `spec` (one thread) over the folding sequence with previous positions; calls
/// each(frame, contacts, stats) after every frame.
void run(const std::string& spec, const std::function<void(std::size_t, const ContactSet&, const DetectorStats&)>& each) {
  const FoldingSequence& seq = folding();
  auto d = make_detector(MethodSpec::parse(spec), {.thickness = seq.thickness(), .threads = 1});
  d->set_topology(seq.mesh().topology_ptr());
  Positions previous;
  for (std::size_t i = 0; i < seq.size(); ++i) {
    const Positions x = seq.positions(i);
    ContactSet got;
    d->update(previous.empty() ? PositionsView{} : PositionsView(previous), x, got);
    each(i, got, d->stats());
    previous = x;
  }
}

/// The full sets, from kdop without a budget (itself checked against naive elsewhere).
const std::vector<ContactSet>& full() {
  static const std::vector<ContactSet> sets = [] {
    std::vector<ContactSet> out;
    run("kdop", [&](std::size_t, const ContactSet& c, const DetectorStats&) { out.push_back(c); });
    return out;
  }();
  return sets;
}

/// Every contact of `got` is in `ref` with identical fields, and `got` is in canonical order.
void expect_subset(const ContactSet& got, const ContactSet& ref, const std::string& what) {
  EXPECT_TRUE(std::is_sorted(got.vf.begin(), got.vf.end(), CanonicalLess{})) << what;
  EXPECT_TRUE(std::is_sorted(got.ee.begin(), got.ee.end(), CanonicalLess{})) << what;
  std::map<std::pair<Index, Index>, const VertexFaceContact*> vf;
  for (const auto& c : ref.vf) vf[{c.vertex, c.face}] = &c;
  std::map<std::pair<Edge, Edge>, const EdgeEdgeContact*> ee;
  for (const auto& c : ref.ee) ee[{c.a, c.b}] = &c;
  for (const auto& c : got.vf) {
    const auto it = vf.find({c.vertex, c.face});
    ASSERT_NE(it, vf.end()) << "false VF contact " << c.vertex << " " << c.face << ", " << what;
    EXPECT_EQ(c.distance, it->second->distance) << what;
    EXPECT_EQ(c.barycentric, it->second->barycentric) << what;
    EXPECT_EQ(c.normal, it->second->normal) << what;
  }
  for (const auto& c : got.ee) {
    const auto it = ee.find({c.a, c.b});
    ASSERT_NE(it, ee.end()) << "false EE contact, " << what;
    EXPECT_EQ(c.distance, it->second->distance) << what;
    EXPECT_EQ(c.s, it->second->s) << what;
    EXPECT_EQ(c.t, it->second->t) << what;
    EXPECT_EQ(c.normal, it->second->normal) << what;
  }
}

/// The same contacts, every field the same bits.
void expect_same(const ContactSet& got, const ContactSet& ref, const std::string& what) {
  EXPECT_EQ(got.vf.size(), ref.vf.size()) << what;
  EXPECT_EQ(got.ee.size(), ref.ee.size()) << what;
  expect_subset(got, ref, what);
}

TEST(KdopCutoff, ParsesItsKeys) {
  for (const char* bad : {"kdop:budget=-1", "kdop:budget=nan", "kdop:pairs=-3", "kdop:budget=2e6", "kdop:clock=sun"}) {
    EXPECT_THROW(make_detector(MethodSpec::parse(bad), {.thickness = 0.1}), InputError) << bad;
  }
  EXPECT_THROW(MethodSpec::parse("hash:pairs=10"), InputError) << "a kdop key only";
  const ExactParams p = ExactParams::from_spec(MethodSpec::parse("kdop:budget=2.5,pairs=100"));
  EXPECT_EQ(p.budget_ms, 2.5);
  EXPECT_EQ(p.pairs, 100u);
  EXPECT_TRUE(p.cut_off());
  EXPECT_FALSE(ExactParams::from_spec(MethodSpec::parse("kdop")).cut_off());
}

// The pair budget: per frame, a subset with the same bits, in canonical order, exactly N pairs
// tested when it cuts, the full set when it does not; growing with N; deterministic.
TEST(KdopCutoff, PairBudgetReturnsAGrowingSubsetWithTheSameBits) {
  const std::vector<ContactSet>& ref = full();
  const std::vector<std::size_t> budgets = {1, 64, 65, 300, 1000, 3000};
  std::vector<std::vector<ContactSet>> sets(budgets.size());
  std::size_t cut_frames = 0, whole_frames = 0, partial_found = 0;
  for (std::size_t b = 0; b < budgets.size(); ++b) {
    const std::size_t n = budgets[b];
    run("kdop:pairs=" + std::to_string(n), [&](std::size_t i, const ContactSet& got, const DetectorStats& st) {
      const std::string what = "pairs=" + std::to_string(n) + ", frame " + std::to_string(i);
      expect_subset(got, ref[i], what);
      const auto tested = static_cast<std::size_t>(st.get("pairs_tested"));
      if (st.get("cut") != 0) {
        ++cut_frames;
        EXPECT_EQ(tested, n) << what;
        EXPECT_EQ(st.get("stages_skipped"), 3) << what;
        const ContactMatch m = match_contacts(got, ref[i]);
        partial_found += m.found < m.reference && m.found > 0 ? 1 : 0;
      } else {
        ++whole_frames;
        EXPECT_LE(tested, n) << what;
        EXPECT_EQ(tested, static_cast<std::size_t>(st.get("candidates"))) << what;
        expect_same(got, ref[i], what);
      }
      sets[b].push_back(got);
    });
  }
  // Both cases occur, and some cut frames hold part of their contacts (not none, not all).
  EXPECT_GT(cut_frames, 20u);
  EXPECT_GT(whole_frames, 20u);
  EXPECT_GT(partial_found, 5u);
  // A larger budget finds everything a smaller one found (the candidates come in one order).
  for (std::size_t b = 0; b + 1 < budgets.size(); ++b) {
    for (std::size_t i = 0; i < ref.size(); ++i) {
      expect_subset(sets[b][i], sets[b + 1][i], "pairs=" + std::to_string(budgets[b]) + " in the next budget's set");
    }
  }
  // The same frames and budget: the same contacts.
  run("kdop:pairs=300", [&](std::size_t i, const ContactSet& got, const DetectorStats&) {
    expect_same(got, sets[3][i], "the same budget again, frame " + std::to_string(i));
  });
}

// A time budget, at its two ends: spent before the first candidate (1 ns, less than the refit
// takes) nothing is tested and nothing reported (after frame 0, which runs the orphan stages
// whole to price them: fails without `pricing` in exact_detector.cpp); never spent, the full set.
// On either clock (wall, or the thread's processor time).
TEST(KdopCutoff, TimeBudgetAtItsEnds) {
  const std::vector<ContactSet>& ref = full();
  for (const std::string clock : {"wall", "cpu"}) {
    run("kdop:budget=1e-6,clock=" + clock, [&](std::size_t i, const ContactSet& got, const DetectorStats& st) {
      EXPECT_EQ(st.get("pairs_tested"), 0) << clock << ", frame " << i;
      // Frame 0 builds the tree and prices the orphan stages by running them whole.
      EXPECT_EQ(st.get("stages_skipped"), i == 0 ? 0 : 3) << clock << ", frame " << i;
      if (i == 0) return;
      EXPECT_TRUE(got.empty()) << clock << ", frame " << i;
      EXPECT_EQ(st.get("cut"), 1) << clock << ", frame " << i;
    });
    run("kdop:budget=1e6,clock=" + clock, [&](std::size_t i, const ContactSet& got, const DetectorStats& st) {
      EXPECT_EQ(st.get("cut"), 0) << clock << ", frame " << i;
      expect_same(got, ref[i], "budget=1e6, clock=" + clock + ", frame " + std::to_string(i));
    });
  }
  // Processor time is one thread's.
  EXPECT_THROW(make_detector(MethodSpec::parse("kdop:budget=1,clock=cpu"), {.thickness = 0.1, .threads = 2}),
               InputError);
}

/// No contact twice (the list is strictly increasing in canonical order).
void expect_no_repeats(const ContactSet& got, const std::string& what) {
  for (std::size_t i = 1; i < got.vf.size(); ++i) ASSERT_TRUE(CanonicalLess{}(got.vf[i - 1], got.vf[i])) << what;
  for (std::size_t i = 1; i < got.ee.size(); ++i) ASSERT_TRUE(CanonicalLess{}(got.ee[i - 1], got.ee[i])) << what;
}

// track=on: the last frame's contacts tested again first, the traversal resumed where it
// stopped. Still a subset with the same bits and no repeats; at the same candidate count it
// finds more on the folding sequence (the seeds' kernel calls come on top: the benchmark
// compares in time).
TEST(KdopCutoff, TrackingFindsMoreAtTheSamePairBudget) {
  const std::vector<ContactSet>& ref = full();
  for (const std::size_t n : {64u, 150u}) {
    ContactMatch plain, tracked;
    run("kdop:pairs=" + std::to_string(n), [&](std::size_t i, const ContactSet& got, const DetectorStats&) {
      plain += match_contacts(got, ref[i]);
    });
    run("kdop:track=on,pairs=" + std::to_string(n), [&](std::size_t i, const ContactSet& got, const DetectorStats&) {
      const std::string what = "track, pairs=" + std::to_string(n) + ", frame " + std::to_string(i);
      expect_subset(got, ref[i], what);
      expect_no_repeats(got, what);
      tracked += match_contacts(got, ref[i]);
    });
    EXPECT_GT(tracked.recall(), plain.recall() + 0.05) << "pairs=" << n << ": " << plain.found << " against " << tracked.found << " of " << plain.reference;
    EXPECT_LT(plain.recall(), 0.9) << "the budget must bite, pairs=" << n;
  }
}

// On a still frame repeated, a quarter of the candidates per frame: the plain cut finds the
// same part every frame; tracking keeps what it found and resumes the traversal, and reaches
// the full set within a few frames.
TEST(KdopCutoff, TrackingOnAStillFrameReachesTheFullSet) {
  shapes::FoldedClothParams params;
  params.n = 24;
  const TriMesh m = shapes::folded_cloth(params);
  const DetectorOptions options{.thickness = params.thickness, .threads = 1};
  auto exact = make_detector(MethodSpec::parse("kdop"), options);
  exact->set_topology(m.topology_ptr());
  ContactSet all;
  exact->update(m.positions(), all);
  const auto quarter = static_cast<std::size_t>(exact->stats().get("candidates")) / 4;
  ASSERT_GT(all.size(), 100u);
  auto plain = make_detector(MethodSpec::parse("kdop:pairs=" + std::to_string(quarter)), options);
  auto tracked = make_detector(MethodSpec::parse("kdop:track=on,pairs=" + std::to_string(quarter)), options);
  plain->set_topology(m.topology_ptr());
  tracked->set_topology(m.topology_ptr());
  std::size_t reached = 0;
  for (std::size_t frame = 0; frame < 12; ++frame) {
    ContactSet p, t;
    plain->update(m.positions(), p);
    tracked->update(m.positions(), t);
    expect_subset(p, all, "plain, frame " + std::to_string(frame));
    expect_subset(t, all, "tracked, frame " + std::to_string(frame));
    expect_no_repeats(t, "tracked, frame " + std::to_string(frame));
    EXPECT_LT(p.size(), all.size()) << "frame " << frame;
    EXPECT_GE(t.size(), p.size()) << "frame " << frame;
    if (t.size() == all.size() && reached == 0) reached = frame + 1;
  }
  EXPECT_GT(reached, 1u) << "a quarter of the candidates cannot find everything at once";
  EXPECT_LE(reached, 8u) << "tracking must reach the full set";
}

/// The candidates of a fresh tree on x, sorted.
std::vector<FacePair> fresh_candidates(const Topology& topo, PositionsView x, Scalar radius) {
  KdopTree tree{KdopParams{}};
  tree.build(topo);
  DetectorStats stats;
  tree.update(FrameInput{{}, x, radius, 1, false, {}}, stats);
  CandidateBuffer buf;
  tree.self_pairs(buf, stats);
  std::vector<FacePair> out;
  for (const auto& c : buf.chunks()) out.insert(out.end(), c.begin(), c.end());
  std::sort(out.begin(), out.end());
  return out;
}

// Regression: a traversal stopped on a refresh frame of the frame-to-frame cache recorded only
// the units it reached; the cache was then marked complete, and the next frame, a rigid
// translation that reuses it, emitted nothing for the other units. Fails without the
// `cache_valid_ = !cut` of kdop_traversal.cpp.
TEST(KdopCutoff, StoppedTraversalLeavesNoIncompleteCache) {
  shapes::FoldedClothParams params;
  const TriMesh m = shapes::folded_cloth(params);
  const Topology& topo = m.topology();
  const Scalar radius = params.thickness;
  Positions a(m.positions().begin(), m.positions().end());
  Positions b = a;
  for (Vec3& p : b) p += Vec3(1e-4, 2e-4, 0);

  KdopTree tree{KdopParams{}};
  tree.build(topo);
  DetectorStats stats;
  tree.update(FrameInput{{}, a, radius, 1, false, {}}, stats);
  CandidateBuffer buf;
  std::size_t streamed = 0;
  buf.set_consumer(
      [&](std::span<const FacePair> chunk) {
        streamed += chunk.size();
        buf.stop();
      },
      1);
  tree.self_pairs(buf, stats);
  buf.set_consumer({});
  ASSERT_EQ(stats.get("coherence"), 1) << "the stopped frame must be a refresh frame";
  const std::vector<FacePair> all_a = fresh_candidates(topo, a, radius);
  ASSERT_GT(streamed, 0u);
  ASSERT_LT(streamed, all_a.size()) << "the stop must leave candidates out";

  tree.update(FrameInput{a, b, radius, 1, false, {}}, stats);
  CandidateBuffer next;
  tree.self_pairs(next, stats);
  std::vector<FacePair> got;
  for (const auto& c : next.chunks()) got.insert(got.end(), c.begin(), c.end());
  std::sort(got.begin(), got.end());
  const std::vector<FacePair> want = fresh_candidates(topo, b, radius);
  // A cache may emit more (its slack), never fewer.
  EXPECT_TRUE(std::includes(got.begin(), got.end(), want.begin(), want.end()))
      << got.size() << " candidates, a fresh tree has " << want.size();
}


/// Streams the self-pairs of a fresh tree on `m` in chunks of `chunk` (1: finely, as a cut-off
/// frame does) to a consumer that stops the buffer after its first chunk, with `poll`; returns
/// the chunk sizes and the candidates of the whole frame.
struct FineStream {
  std::vector<std::size_t> chunks;
  std::size_t all = 0;
  double tasks = 0;
};
FineStream stream_stopped(const TriMesh& m, Scalar radius, std::size_t chunk, std::function<bool()> poll = {}) {
  KdopTree tree{KdopParams{}};
  tree.build(m.topology());
  DetectorStats stats;
  tree.update(FrameInput{{}, m.positions(), radius, 1, false, {}}, stats);
  FineStream out;
  CandidateBuffer buf;
  buf.set_consumer(
      [&](std::span<const FacePair> c) {
        out.chunks.push_back(c.size());
        buf.stop();
      },
      chunk, false, std::move(poll));
  tree.self_pairs(buf, stats);
  buf.set_consumer({});
  out.tasks = stats.get("tasks");
  out.all = fresh_candidates(m.topology(), m.positions(), radius).size();
  return out;
}

// A cut-off frame looks at its budget every few dozen candidates (a leaf's emission), not once
// per traversal task (a task may be a whole coherence unit of hundreds of faces, whose
// candidates were produced whole before the budget was looked at): the first chunk handed over
// finely is a fraction of the one handed over per task (chunk 64: at the end of the first
// task), and nothing follows the stop. Fails without `hand_over` in kdop_traversal.cpp (both
// were the first task's candidates).
TEST(KdopCutoff, FineStreamStopsInsideATask) {
  shapes::FoldedClothParams params;
  params.n = 24;
  const TriMesh m = shapes::folded_cloth(params);
  const FineStream fine = stream_stopped(m, params.thickness, 1);
  const FineStream per_task = stream_stopped(m, params.thickness, 64);
  ASSERT_EQ(fine.chunks.size(), 1u) << "nothing after the stop";
  ASSERT_EQ(per_task.chunks.size(), 1u);
  EXPECT_LT(4 * fine.chunks[0], per_task.chunks[0])
      << "of " << fine.all << " candidates in " << fine.tasks << " tasks";
}

// Between candidates the traversal asks the consumer's poll (a stretch of box tests may find
// none): a poll that says stop at once stops the traversal before any candidate, one that says
// so at its k-th call after about 16 k node visits. Fails without `halted` in kdop_traversal.cpp.
TEST(KdopCutoff, FineStreamPollsBetweenCandidates) {
  shapes::FoldedClothParams params;
  params.n = 24;
  const TriMesh m = shapes::folded_cloth(params);
  std::size_t calls = 0;
  const FineStream at_once = stream_stopped(m, params.thickness, 1, [&] { return ++calls >= 1; });
  EXPECT_TRUE(at_once.chunks.empty()) << "the first visit polls";
  EXPECT_EQ(calls, 1u);
  // Stopped by its poll, or by the consumer after a first chunk, within a few dozen visits.
  std::size_t later_calls = 0;
  const FineStream later = stream_stopped(m, params.thickness, 1, [&] { return ++later_calls >= 3; });
  EXPECT_LE(later_calls, 3u);
  EXPECT_LE(later.chunks.size(), 1u);
}

}  // namespace
}  // namespace crumple
