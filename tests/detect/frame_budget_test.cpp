// The frame budget shared by `kdop`, `stochastic` and `hybrid`, counted rather than timed:
// the deadline's reserve on a test clock (core/frame_deadline.hpp: work stops while a stage of
// the reserved cost still fits); the `budget` and `clock` keys parsed in one place
// (detect/budget_spec_detail.hpp) with the same errors for the three methods;
// `Detector::set_budget`, a budget that changes between frames (spent at once: nothing tested,
// nothing reported; 0: the unbudgeted contacts, and the saved state of the spec's parameters).
// Then the one timed check the issue allows: `kdop` keeps a per-frame budget of half its own
// processor time on a quiet machine within a generous bound.
#include <crumple/core/error.hpp>
#include <crumple/core/frame_deadline.hpp>
#include <crumple/detect/budget_spec_detail.hpp>
#include <crumple/detect/compare.hpp>
#include <crumple/detect/detector.hpp>
#include <crumple/mesh/shapes.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <ctime>
#include <string>
#include <vector>

namespace crumple {
namespace {

double g_now_ms = 0;
double test_now() { return g_now_ms; }

TEST(FrameDeadline, ReserveStopsWorkWhileTheReservedStageStillFits) {
  for (const BudgetClock clock : {BudgetClock::wall, BudgetClock::cpu}) {
    g_now_ms = 100;
    const FrameDeadline d(10, clock, test_now);
    EXPECT_TRUE(d.active());
    EXPECT_FALSE(d.passed());
    EXPECT_FALSE(d.passed(9.5));
    EXPECT_TRUE(d.passed(10)) << "a reserve of the whole budget leaves no time for work";
    EXPECT_TRUE(d.passed(25));
    g_now_ms = 107;
    EXPECT_EQ(d.now_ms(), 7);
    EXPECT_FALSE(d.passed(2.5));
    EXPECT_TRUE(d.passed(3));
    EXPECT_FALSE(d.passed());
    EXPECT_FALSE(d.passed(-1)) << "a negative reserve is none";
    g_now_ms = 110;
    EXPECT_TRUE(d.passed());
    EXPECT_TRUE(d.passed(-1));
  }
  g_now_ms = 0;
  const FrameDeadline none(0, BudgetClock::cpu, test_now);
  g_now_ms = 1e9;
  EXPECT_FALSE(none.active());
  EXPECT_FALSE(none.passed());
  EXPECT_FALSE(none.passed(1e12)) << "no budget: never passed, whatever the reserve";
  EXPECT_EQ(none.now_ms(), 1e9);
}

// Without a test clock the reserve is read on the real clocks: a budget of an hour has not
// passed with a reserve of a minute, and has with a reserve of two hours.
TEST(FrameDeadline, ReserveOnTheRealClocks) {
  for (const BudgetClock clock : {BudgetClock::wall, BudgetClock::cpu}) {
    const FrameDeadline d(3.6e6, clock);
    EXPECT_FALSE(d.passed(6e4));
    EXPECT_TRUE(d.passed(7.2e6));
    EXPECT_GE(d.now_ms(), 0);
  }
}

TEST(BudgetSpec, OneParserForTheThreeMethods) {
  for (const std::string method : {"kdop", "stochastic", "hybrid"}) {
    SCOPED_TRACE(method);
    const BudgetSpec none = budget_from_spec(MethodSpec::parse(method));
    EXPECT_EQ(none.budget_ms, 0);
    EXPECT_EQ(none.clock, BudgetClock::wall);
    const BudgetSpec b = budget_from_spec(MethodSpec::parse(method + ":budget=2.5,clock=cpu"));
    EXPECT_EQ(b.budget_ms, 2.5);
    EXPECT_EQ(b.clock, BudgetClock::cpu);
    for (const char* bad : {"-1", "2e6"}) {
      const MethodSpec spec = MethodSpec::parse(method + ":budget=" + bad);
      try {
        budget_from_spec(spec);
        ADD_FAILURE() << "budget=" << bad << " accepted";
      } catch (const InputError& e) {
        EXPECT_EQ(std::string(e.what()), "method " + spec.to_string() + ": budget must be in [0, 1e6] ms (0 = none)");
      }
      EXPECT_THROW(make_detector(spec, {.thickness = 0.1, .threads = 1}), InputError) << bad;
    }
    for (const char* bad : {"budget=nan", "budget=inf", "budget=x", "clock=sun"}) {
      EXPECT_THROW(budget_from_spec(MethodSpec::parse(method + ":" + bad)), InputError) << bad;
    }
  }
}

const FoldingSequence& folding() {
  static const FoldingSequence s({.n = 16, .frames = 12, .seed = 7});
  return s;
}

std::unique_ptr<Detector> make(const std::string& spec) {
  auto d = make_detector(MethodSpec::parse(spec), {.thickness = folding().thickness(), .threads = 1});
  d->set_topology(folding().mesh().topology_ptr());
  return d;
}

TEST(SetBudget, OnlyForMethodsWithABudgetAndInRange) {
  EXPECT_THROW(make("naive")->set_budget(1), InputError);
  EXPECT_THROW(make("hash")->set_budget(1), InputError);
  for (const char* spec : {"kdop", "stochastic", "hybrid"}) {
    auto d = make(spec);
    for (const double bad : {-1.0, 2e6, std::nan("")}) EXPECT_THROW(d->set_budget(bad), InputError) << spec << bad;
    EXPECT_NO_THROW(d->set_budget(0));
    EXPECT_NO_THROW(d->set_budget(2.5));
  }
  // Processor time is one thread's: kdop with clock=cpu takes a budget only on one thread.
  auto two = make_detector(MethodSpec::parse("kdop:clock=cpu"), {.thickness = 0.1, .threads = 2});
  EXPECT_THROW(two->set_budget(1), InputError);
  EXPECT_NO_THROW(two->set_budget(0));
}

// Frame by frame, a budget set between frames replaces the spec's: alternately spent at once
// (nothing tested, nothing reported) and none (kdop: the contacts without a budget, every field
// the same bits; the stochastic searches: true contacts). Set to 0 on every frame, the
// detector is the method without a budget, contacts and saved state (whose parameters stay
// the spec's) alike.
TEST(SetBudget, ChangesBetweenFrames) {
  auto exact = make("kdop");
  for (const std::string method : {"kdop", "hybrid", "stochastic:variant=direct"}) {
    SCOPED_TRACE(method);
    const std::string budgeted = method + (method.find(':') == std::string::npos ? ":" : ",") + "budget=1e6";
    auto plain = make(method);
    auto a = make(budgeted);  // the spec's budget never bites; set_budget replaces it
    auto b = make(budgeted);
    auto e = make(budgeted);
    ContactSet ref, want, got, other, unset;
    std::size_t found = 0;
    for (std::size_t i = 0; i < folding().size(); ++i) {
      const Positions x = folding().positions(i);
      exact->update(x, ref);
      plain->update(x, want);
      b->set_budget(0);
      b->update(x, other);
      e->update(x, unset);
      EXPECT_EQ(other.size(), want.size()) << "frame " << i;
      EXPECT_EQ(match_contacts(other, want).missed, 0u) << "frame " << i;
      EXPECT_EQ(match_contacts(unset, want).missed, 0u) << "frame " << i;
      const bool spend = i % 3 == 1;
      a->set_budget(spend ? 1e-6 : 0);
      a->update(x, got);
      if (spend) {
        EXPECT_TRUE(got.empty()) << "frame " << i;
        if (method == "kdop") {
          EXPECT_EQ(a->stats().get("pairs_tested"), 0) << "frame " << i;
        }
        if (method == "hybrid") {
          EXPECT_EQ(a->stats().get("zones_examined"), 0) << "frame " << i;
        }
        continue;
      }
      found += got.size();
      const ContactMatch m = match_contacts(got, ref);
      EXPECT_EQ(m.false_contacts, 0u) << "frame " << i;
      if (method == "kdop") {
        EXPECT_EQ(m.missed, 0u) << "frame " << i;
        for (std::size_t k = 0; k < std::min(got.vf.size(), ref.vf.size()); ++k) {
          EXPECT_EQ(got.vf[k].distance, ref.vf[k].distance) << "frame " << i;
        }
      }
    }
    EXPECT_GT(found, 0u) << "the frames without a budget find contacts";
    EXPECT_GT(want.size(), 0u) << "the last frame has contacts";
    EXPECT_EQ(b->save_state(), e->save_state());
    EXPECT_NO_THROW(e->load_state(b->save_state()));
  }
}

double thread_cpu_ms() {
  timespec t{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return static_cast<double>(t.tv_sec) * 1e3 + static_cast<double>(t.tv_nsec) * 1e-6;
}

// The budget covers the whole call (refit, traversal, orphan stages, gather): with each
// frame's budget half of kdop's own processor time on that frame (`set_budget`), the frames'
// processor time stays within a generous bound of their budget: 1.6x at the median (an ignored
// budget gives 2x), 3x at the 90th percentile. The goal, 1.1x at the 99th, is a
// benchmark's question (docs/benchmarks/hybrid.md): a traversal task's candidates are produced
// whole before the budget is looked at. Contacts stay a true subset.
TEST(KdopCutoff, PerFrameBudgetKeptWithinAGenerousBound) {
#ifdef CRUMPLE_SANITIZED
  GTEST_SKIP() << "processor times under the sanitizers say nothing of the Release build";
#endif
  const FoldingSequence seq({.n = 48, .frames = 24, .seed = 2});
  const DetectorOptions options{.thickness = seq.thickness(), .threads = 1};
  auto exact = make_detector(MethodSpec::parse("kdop"), options);
  auto cut = make_detector(MethodSpec::parse("kdop:clock=cpu"), options);
  exact->set_topology(seq.mesh().topology_ptr());
  cut->set_topology(seq.mesh().topology_ptr());
  std::vector<double> over;
  std::size_t found = 0, bitten = 0;
  ContactSet ref, got;
  Positions previous;
  for (std::size_t i = 0; i < seq.size(); ++i) {
    const Positions x = seq.positions(i);
    const PositionsView prev = previous.empty() ? PositionsView{} : PositionsView(previous);
    double t = 1e300;
    for (int k = 0; k < 2; ++k) {  // the lesser of two runs: the scheduler only adds
      const double t0 = thread_cpu_ms();
      exact->update(prev, x, ref);
      t = std::min(t, thread_cpu_ms() - t0);
    }
    const double budget = t / 2;
    cut->set_budget(budget);
    const double t0 = thread_cpu_ms();
    cut->update(prev, x, got);
    const double spent = thread_cpu_ms() - t0;
    const ContactMatch m = match_contacts(got, ref);
    EXPECT_EQ(m.false_contacts, 0u) << "frame " << i;
    found += got.size();
    bitten += m.missed > 0 ? 1 : 0;
    if (i > 0) over.push_back(spent / budget);  // frame 0 builds the tree
    previous = x;
  }
  EXPECT_GE(bitten, seq.size() / 2) << "the budget must bite";
  EXPECT_GT(found, 0u);
  std::sort(over.begin(), over.end());
  EXPECT_LE(over[over.size() / 2], 1.6);
  EXPECT_LE(over[over.size() * 9 / 10], 3.0);
  std::printf("[ budget ] processor time / budget: median %.3f, 90th percentile %.3f, max %.3f\n",
              over[over.size() / 2], over[over.size() * 9 / 10], over.back());
}

}  // namespace
}  // namespace crumple
