#pragma once
/// \file
/// A frame's time budget (the `budget` keys of `kdop`, `stochastic` and `hybrid`), counted on
/// the wall clock or on the calling thread's processor time (`clock=cpu`: what a frame costs
/// without the time the scheduler gave to other processes, for measuring budgets on a shared
/// machine; one thread).

#include <algorithm>
#include <atomic>
#include <chrono>
#include <ctime>
#include <stdexcept>
#include <string>
#include <string_view>

namespace crumple {

/// The clock a frame budget counts on.
enum class BudgetClock { wall, cpu };

/// `wall` or `cpu` (the spec keys' values); throws std::invalid_argument otherwise.
inline BudgetClock parse_budget_clock(std::string_view text) {
  if (text == "wall") return BudgetClock::wall;
  if (text == "cpu") return BudgetClock::cpu;
  throw std::invalid_argument("clock must be wall or cpu, got '" + std::string(text) + "'");
}

/// The deadline `budget_ms` after construction on `clock`; none when budget_ms <= 0 (then
/// `passed` is always false). Not thread-safe with `BudgetClock::cpu`: checked by the thread
/// that made it.
///
/// The stages of a frame that no budget can cut (the gather of the result, a stage that runs
/// whole or not at all) are kept inside the budget by a reserve: `passed(r)` is true once less
/// than r ms are left, so that work stops early enough for a stage of cost r to end within the
/// budget. `now_ms` reads the budget's own clock, to measure those stages for the next frame.
class FrameDeadline {
 public:
  using Wall = std::chrono::steady_clock;
  /// A clock for tests: milliseconds from any origin, nondecreasing. It replaces both the wall
  /// and the processor clock (the deadline then depends only on its readings).
  using TestClock = double (*)();
  FrameDeadline() = default;
  FrameDeadline(double budget_ms, BudgetClock clock, TestClock test_clock = nullptr)
      : active_(budget_ms > 0), clock_(clock), test_clock_(test_clock), start_(Wall::now()),
        wall_(start_ + to_duration(budget_ms)) {
    if (test_clock_ != nullptr || clock_ == BudgetClock::cpu) {
      origin_ms_ = test_clock_ != nullptr ? test_clock_() : thread_cpu_ms();
      end_ms_ = origin_ms_ + budget_ms;
    }
  }
  bool active() const { return active_; }
  /// The same deadline, `ms` earlier (same start and clock): for work that must leave `ms` of
  /// the budget to what follows it (`passed(r)` on the copy is `passed(r + ms)` here). A budget
  /// that `ms` uses up is passed at the first look.
  FrameDeadline shortened(double ms) const {
    FrameDeadline d = *this;
    if (!active_ || !(ms > 0)) return d;
    d.wall_ -= to_duration(ms);
    d.end_ms_ -= ms;
    return d;
  }
  /// True once less than `reserve_ms` of the budget is left (reserve 0: once it is spent). The
  /// processor clock (a system call, microseconds) is read only when the wall clock has
  /// advanced by what was left of the budget at the last reading, less the reserve: a thread
  /// cannot use more processor time than wall time.
  /// Once the budget itself is spent the answer is kept, clocks unread (a loop that checks
  /// its deadline per item then costs nothing more past it).
  bool passed(double reserve_ms = 0) const {
    if (!active_) return false;
    if (spent_.value.load(std::memory_order_relaxed)) return true;
    reserve_ms = std::max(reserve_ms, 0.0);
    bool out = false;
    double left = 0;
    if (test_clock_ != nullptr) {
      left = end_ms_ - test_clock_();
      out = left <= reserve_ms;
    } else {
      const Wall::time_point now = Wall::now();
      if (reserve_ms > 0 ? now + to_duration(reserve_ms) < wall_ : now < wall_) return false;
      if (clock_ == BudgetClock::wall) {
        left = std::chrono::duration<double, std::milli>(wall_ - now).count();
        out = true;
      } else {
        left = end_ms_ - thread_cpu_ms();
        out = left <= reserve_ms + kResolutionMs;
        if (!out) wall_ = now + to_duration(left);
      }
    }
    if (out && left <= (test_clock_ != nullptr ? 0 : kResolutionMs)) spent_.value.store(true, std::memory_order_relaxed);
    return out;
  }
  /// The budget's clock in ms from construction: processor time with `BudgetClock::cpu`, wall
  /// time otherwise (a test clock's readings when one was given). For measuring stages.
  double now_ms() const {
    if (test_clock_ != nullptr) return test_clock_() - origin_ms_;
    if (clock_ == BudgetClock::cpu) return thread_cpu_ms() - origin_ms_;
    return elapsed_ms();
  }
  /// Milliseconds on the wall clock since construction.
  double elapsed_ms() const { return std::chrono::duration<double, std::milli>(Wall::now() - start_).count(); }

 private:
  static constexpr double kResolutionMs = 0.002;
  static Wall::duration to_duration(double ms) {
    return std::chrono::duration_cast<Wall::duration>(std::chrono::duration<double, std::milli>(ms));
  }
  static double thread_cpu_ms() {
    timespec t{};
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
    return static_cast<double>(t.tv_sec) * 1e3 + static_cast<double>(t.tv_nsec) * 1e-6;
  }

  bool active_ = false;
  BudgetClock clock_ = BudgetClock::wall;
  TestClock test_clock_ = nullptr;
  Wall::time_point start_{};
  mutable Wall::time_point wall_{};  ///< no need to look before this
  /// Set once the budget itself is spent. Atomic: a wall-clock deadline is shared by the
  /// threads of a cut-off frame (`wall_` is written only on the processor clock, which is
  /// checked by one thread). A copy takes the value.
  struct SpentFlag {
    std::atomic<bool> value{false};
    SpentFlag() = default;
    SpentFlag(const SpentFlag& other) : value(other.value.load(std::memory_order_relaxed)) {}
    SpentFlag& operator=(const SpentFlag& other) {
      value.store(other.value.load(std::memory_order_relaxed), std::memory_order_relaxed);
      return *this;
    }
  };
  mutable SpentFlag spent_;
  double origin_ms_ = 0;              ///< cpu or test clock: its reading at construction
  double end_ms_ = 0;                 ///< cpu or test clock: its reading at which the budget ends
};

/// The cost of a stage that a budget cannot cut, for reserving it from later frames' budgets:
/// the largest of its measurements, each older one worth 10% less per measurement since, so
/// that a stage whose cost varies between frames is reserved at its dear end. 0 until measured.
class StageCost {
 public:
  void measured(double ms) { ms_ = std::max(ms, kDecay * ms_); }
  double ms() const { return ms_; }

 private:
  static constexpr double kDecay = 0.9;
  double ms_ = 0;
};

}  // namespace crumple
