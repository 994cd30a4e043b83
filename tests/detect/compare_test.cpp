// The recall/precision harness (detect/compare.hpp) and its built-in folding sequence.
#include <crumple/core/error.hpp>
#include <crumple/detect/compare.hpp>
#include <crumple/detect/detector.hpp>
#include <crumple/mesh/shapes.hpp>

#include <gtest/gtest.h>

namespace crumple {
namespace {

VertexFaceContact vf(Index v, Index f) {
  VertexFaceContact c;
  c.vertex = v;
  c.face = f;
  return c;
}

EdgeEdgeContact ee(Edge a, Edge b) {
  EdgeEdgeContact c;
  c.a = a;
  c.b = b;
  return c;
}

TEST(Compare, MatchesContactsByIdentity) {
  ContactSet ref, got;
  ref.vf = {vf(0, 5), vf(1, 5), vf(3, 2)};
  ref.ee = {ee({0, 1}, {4, 5}), ee({0, 2}, {6, 7})};
  got.vf = {vf(1, 5), vf(2, 9), vf(3, 2)};
  got.ee = {ee({0, 2}, {6, 7})};
  got.tt = {{1, 8}};
  const ContactMatch m = match_contacts(got, ref);
  EXPECT_EQ(m.reference, 5u);
  EXPECT_EQ(m.reported, 5u);
  EXPECT_EQ(m.found, 3u);
  EXPECT_EQ(m.missed, 2u);
  EXPECT_EQ(m.false_contacts, 2u);
  EXPECT_DOUBLE_EQ(m.recall(), 0.6);
  EXPECT_DOUBLE_EQ(m.precision(), 0.6);
  const ContactMatch empty = match_contacts({}, {});
  EXPECT_EQ(empty.recall(), 1.0);
  EXPECT_EQ(empty.precision(), 1.0);
}

TEST(Compare, FoldingSequenceIsDeterministicAndGainsContacts) {
  const FoldingSequence a({.n = 16, .frames = 12, .seed = 4}), b({.n = 16, .frames = 12, .seed = 4}),
      c({.n = 16, .frames = 12, .seed = 5});
  EXPECT_EQ(a.size(), 12u);
  EXPECT_EQ(a.mesh().num_faces(), 512);
  EXPECT_DOUBLE_EQ(a.thickness(), 0.25 / 16);
  EXPECT_EQ(a.positions(7), b.positions(7));
  EXPECT_NE(a.positions(7), c.positions(7));
  EXPECT_NE(a.name(3).find("#3"), std::string::npos);
  EXPECT_THROW(a.positions(12), PreconditionError);
  EXPECT_THROW(FoldingSequence({.n = 1}), InputError);
  auto naive = make_detector(MethodSpec(Method::Naive), {.thickness = a.thickness()});
  const ReferenceRun run = run_reference(*naive, a);
  ASSERT_EQ(run.contacts.size(), 12u);
  EXPECT_TRUE(run.contacts.front().empty()) << "the layers start apart";
  EXPECT_FALSE(run.contacts.back().empty()) << "and end up crossing";
}

TEST(Compare, ReferenceAgainstItselfIsPerfectAndBothEntryPointsAgree) {
  const FoldingSequence seq({.n = 16, .frames = 10, .seed = 2});
  auto naive = make_detector(MethodSpec(Method::Naive), {.thickness = seq.thickness()});
  auto other = make_detector(MethodSpec(Method::Naive), {.thickness = seq.thickness()});
  std::size_t frames_seen = 0;
  const ComparisonSummary s = compare_detectors(*naive, *other, seq, [&](const FrameComparison& f) {
    EXPECT_EQ(f.frame, frames_seen++);
    EXPECT_EQ(f.match.found, f.match.reference);
    EXPECT_EQ(f.match.false_contacts, 0u);
    EXPECT_GE(f.ms, 0);
    EXPECT_GE(f.reference_ms, 0);
  });
  EXPECT_EQ(s.frames, 10u);
  EXPECT_EQ(frames_seen, 10u);
  EXPECT_EQ(s.total.recall(), 1.0);
  EXPECT_EQ(s.min_recall, 1.0);
  EXPECT_GT(s.total.reference, 0u);

  auto sto = make_detector(MethodSpec::parse("stochastic:setting=1"), {.thickness = seq.thickness()});
  const ComparisonSummary live = compare_detectors(*sto, *other, seq);
  const ReferenceRun run = run_reference(*other, seq);
  const ComparisonSummary cached = compare_detectors(*sto, run, seq);
  EXPECT_EQ(live.total.found, cached.total.found);
  EXPECT_EQ(live.total.reference, cached.total.reference);
  EXPECT_EQ(cached.total.false_contacts, 0u);
  EXPECT_LE(cached.min_recall, cached.total.recall());

  ReferenceRun short_run = run;
  short_run.contacts.pop_back();
  EXPECT_THROW(compare_detectors(*sto, short_run, seq), PreconditionError);
}

TEST(Compare, VectorFramesWrapPositions) {
  const TriMesh m = shapes::lattice(3, 3);
  const VectorFrames frames(m, {m.positions(), m.positions()}, "flat");
  EXPECT_EQ(frames.size(), 2u);
  EXPECT_EQ(frames.name(1), "flat#1");
  EXPECT_THROW(VectorFrames(m, {Positions(2, Vec3::Zero())}), PreconditionError);
  auto a = make_detector(MethodSpec(Method::Naive), {.thickness = 0.01});
  auto b = make_detector(MethodSpec(Method::Naive), {.thickness = 0.01});
  EXPECT_EQ(compare_detectors(*a, *b, frames).total.reference, 0u);
}

}  // namespace
}  // namespace crumple
