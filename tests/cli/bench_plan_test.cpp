// The timing plans of `crumple bench` (apps/cli/bench_suite): which frames a timing run feeds,
// with which motion, and which of them it times. A wrong plan only changes timings, so the
// end-to-end run of bench_test.cpp would not notice it: the plans are checked here directly.
#include <gtest/gtest.h>

#include <report/bench_suite.hpp>

#include <crumple/detect/compare.hpp>

#include <vector>

namespace crumple::bench {
namespace {

TEST(BenchPlan, StepsFeedTheFramesInOrderEachWithTheMotionFromTheOneBefore) {
  const TimingPlan plan{.first = 2, .timed_from = 4, .last = 7, .repetitions = 1};
  const std::vector<FeedStep> expected{
      {.frame = 2, .previous = 2, .timed = false},  // the first update of a run: no motion
      {.frame = 3, .previous = 2, .timed = false},
      {.frame = 4, .previous = 3, .timed = true},
      {.frame = 5, .previous = 4, .timed = true},
      {.frame = 6, .previous = 5, .timed = true},
  };
  EXPECT_EQ(feed_steps(plan), expected);
}

TEST(BenchPlan, RealFramePairIsTimedOnItsSecondFrameWithItsMotionAfterAWarmUp) {
  // The bug this guards against: the second frame fed as its own previous (no motion), with no
  // untimed update before it.
  const TimingPlan plan = frame_pair_plan(5);
  EXPECT_EQ(plan.repetitions, 5);
  const std::vector<FeedStep> expected{{.frame = 0, .previous = 0, .timed = false},
                                       {.frame = 1, .previous = 0, .timed = true}};
  EXPECT_EQ(feed_steps(plan), expected);
}

TEST(BenchPlan, LatticeWarmsUpOnTwoFramesThenTimesEachWithItsMotion) {
  for (const std::size_t timed : {std::size_t{1}, std::size_t{3}, std::size_t{6}}) {
    const TimingPlan plan = lattice_scaling_plan(timed, 2);
    EXPECT_EQ(plan.repetitions, 2);
    std::size_t warm_ups = 0, timed_steps = 0;
    for (const FeedStep& step : feed_steps(plan)) {
      EXPECT_GE(step.previous, plan.first) << "motion from a frame that is never fed";
      if (!step.timed) {
        EXPECT_EQ(timed_steps, 0u) << "a warm-up after a timed update";
        ++warm_ups;
        continue;
      }
      ++timed_steps;
      EXPECT_EQ(step.previous + 1, step.frame) << "frame " << step.frame << " timed without its motion";
    }
    EXPECT_EQ(warm_ups, 2u);
    EXPECT_EQ(timed_steps, timed);
  }
}

TEST(BenchPlan, TimingRunsTimeExactlyThePlansTimedFrames) {
  const FoldingSequence seq({.n = 6, .frames = 12, .seed = 3});
  std::vector<Positions> frames;
  for (std::size_t i = 0; i < seq.size(); ++i) frames.push_back(seq.positions(i));
  const DetectorOptions options{.thickness = seq.thickness(), .kinds = {}, .threads = 1};
  const TimingPlan plan = lattice_scaling_plan(3, 2);
  int runs = 0;
  const std::vector<Timing> t = time_methods_against_first(seq.mesh().topology_ptr(), frames, {"naive", "kdop"},
                                                           options, plan, [&](int, std::size_t) { ++runs; });
  EXPECT_EQ(runs, 4);  // 2 repetitions × 2 methods
  ASSERT_EQ(t.size(), 2u);
  for (const Timing& timing : t) {
    EXPECT_EQ(timing.ms.size(), 3u);
    ASSERT_EQ(timing.match.size(), 3u);
    for (const ContactMatch& m : timing.match) EXPECT_EQ(m.found, m.reference);  // kdop is exact
  }
}

}  // namespace
}  // namespace crumple::bench
