#pragma once
/// \file
/// The `budget` and `clock` keys shared by the budgeted methods (`kdop`, `stochastic`,
/// `hybrid`), parsed and checked in one place.

#include <crumple/core/frame_deadline.hpp>
#include <crumple/detect/method.hpp>

#include <string>

namespace crumple {

/// A frame's time budget as a method spec gives it.
struct BudgetSpec {
  double budget_ms = 0;  ///< per frame, 0 = none [budget]
  BudgetClock clock = BudgetClock::wall;  ///< what budget_ms counts [clock]
};

/// Throws `InputError` ("method NAME: budget must be in [0, 1e6] ms (0 = none)") unless
/// 0 <= ms <= 1e6.
void check_budget_ms(double ms, const std::string& method);

/// `budget` (default 0, in [0, 1e6] ms) and `clock` (`wall` or `cpu`, default `wall`) of `spec`;
/// throws `InputError` naming the method otherwise.
BudgetSpec budget_from_spec(const MethodSpec& spec);

}  // namespace crumple
