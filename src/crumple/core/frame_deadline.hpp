#pragma once
/// \file
/// A frame's time budget (the `budget` keys of `kdop`, `stochastic` and `hybrid`), counted on
/// the wall clock or on the calling thread's processor time (`clock=cpu`: what a frame costs
/// without the time the scheduler gave to other processes, for measuring budgets on a shared
/// machine; one thread).

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
class FrameDeadline {
 public:
  using Wall = std::chrono::steady_clock;
  FrameDeadline() = default;
  FrameDeadline(double budget_ms, BudgetClock clock)
      : active_(budget_ms > 0), clock_(clock), start_(Wall::now()), wall_(start_ + to_duration(budget_ms)) {
    if (active_ && clock_ == BudgetClock::cpu) cpu_end_ms_ = thread_cpu_ms() + budget_ms;
  }
  bool active() const { return active_; }
  /// True once the budget is spent. The processor clock (a system call, microseconds) is read
  /// only when the wall clock has advanced by what was left of the budget at the last reading:
  /// a thread cannot use more processor time than wall time.
  bool passed() const {
    if (!active_) return false;
    const Wall::time_point now = Wall::now();
    if (now < wall_) return false;
    if (clock_ == BudgetClock::wall) return true;
    const double left = cpu_end_ms_ - thread_cpu_ms();
    if (left <= kResolutionMs) return true;
    wall_ = now + to_duration(left);
    return false;
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
  Wall::time_point start_{};
  mutable Wall::time_point wall_{};  ///< no need to look before this
  double cpu_end_ms_ = 0;            ///< the thread's processor time at which the budget ends
};

}  // namespace crumple
