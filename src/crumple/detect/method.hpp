#pragma once
/// \file
/// Detection methods: the enum, their descriptions and the `NAME[:key=value,...]` spec syntax,
/// parsed in one place for the CLI, the benchmarks and the tests.

#include <crumple/core/types.hpp>

#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace crumple {

/// Every detection method crumple offers.
enum class Method {
  Naive,       ///< the thesis' O(n^2) double loop; the exact reference (oracle)
  Stochastic,  ///< the thesis' contribution: random pairs + temporal coherence (stochastic.hpp)
  Kdop,        ///< exact: inflated motion-oriented k-DOP hierarchy (kdop_tree.hpp)
  Hash,        ///< exact: spatial hashing (hash_grid.hpp)
  Sap,         ///< exact: sweep and prune, insertion sort across frames (sweep_prune.hpp)
  Hybrid,      ///< stochastic search inside a coarse hierarchy's zones, time budget (hybrid.hpp)
};

/// What a method guarantees, for tests and tools that treat methods generically.
struct Capabilities {
  bool exact = false;        ///< returns exactly the reference contact set
  bool stochastic = false;   ///< may miss contacts; quality depends on parameters and seed
  bool uses_motion = false;  ///< uses the previous positions when given
};

/// One key a method spec accepts.
struct ParamInfo {
  std::string_view key;
  std::string_view default_value;
  std::string_view description;
};

/// Static description of a method.
struct MethodInfo {
  Method method;
  std::string_view name;
  std::string_view summary;
  Capabilities capabilities;
  std::span<const ParamInfo> params;
};

/// All methods, in enum order.
std::span<const MethodInfo> all_methods();
const MethodInfo& method_info(Method method);
std::string_view to_string(Method method);
/// Throws `InputError` listing the valid names.
Method parse_method(std::string_view name);

/// A method and its parameters, e.g. `naive` or `stochastic:variant=vertex,active=100`.
class MethodSpec {
 public:
  MethodSpec() = default;
  explicit MethodSpec(Method method) : method_(method) {}

  /// Parses `NAME[:key=value,...]`. Unknown names or keys, a key given twice or a malformed
  /// item throw `InputError` whose message lists the valid names or keys.
  static MethodSpec parse(std::string_view text);

  Method method() const { return method_; }
  /// Parameters as given, in order.
  const std::vector<std::pair<std::string, std::string>>& params() const { return params_; }
  /// Sets (or replaces) a parameter; the key must be valid for the method.
  MethodSpec& set(std::string key, std::string value);

  std::optional<std::string> get(std::string_view key) const;
  /// Typed getters: the value, or the fallback when absent; a malformed value throws
  /// `InputError` naming the method, the key and what was expected.
  long long get_int(std::string_view key, long long fallback) const;
  double get_double(std::string_view key, double fallback) const;
  bool get_bool(std::string_view key, bool fallback) const;  ///< on/off, true/false, 1/0
  std::string get_choice(std::string_view key, std::string_view fallback,
                         std::span<const std::string_view> choices) const;

  /// Canonical text, `parse(to_string())` gives back the same spec.
  std::string to_string() const;

 private:
  [[noreturn]] void bad_value(std::string_view key, const std::string& value,
                              std::string_view expected) const;

  Method method_ = Method::Naive;
  std::vector<std::pair<std::string, std::string>> params_;
};

}  // namespace crumple
