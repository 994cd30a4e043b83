#include <crumple/core/error.hpp>
#include <crumple/detect/budget_spec_detail.hpp>

#include <array>
#include <string_view>

namespace crumple {

void check_budget_ms(double ms, const std::string& method) {
  if (!(ms >= 0 && ms <= 1e6)) throw InputError("method " + method + ": budget must be in [0, 1e6] ms (0 = none)");
}

BudgetSpec budget_from_spec(const MethodSpec& spec) {
  BudgetSpec b;
  b.budget_ms = spec.get_double("budget", 0);
  check_budget_ms(b.budget_ms, spec.to_string());
  static constexpr std::array<std::string_view, 2> kClock{"wall", "cpu"};
  b.clock = parse_budget_clock(spec.get_choice("clock", "wall", kClock));
  return b;
}

}  // namespace crumple
