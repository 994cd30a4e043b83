#pragma once
/// \file
/// The `NAME[:key=value,...]` syntax shared by method specs (`detect/method.hpp`) and scene
/// specs (`sim/scene.hpp`): splitting, trimming, typed values and the canonical text. Each user
/// checks names and keys against its own table.

#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace crumple {

/// A spec split into its name and `key=value` items, both trimmed of spaces and tabs.
struct SpecText {
  std::string name;
  std::vector<std::pair<std::string, std::string>> items;

  /// Splits `text`. Empty items (`a=1,,b=2`, a trailing comma) are skipped. An item without
  /// '=' or with an empty key throws `InputError` "<what> '<text>': expected key=value, got
  /// '<item>'" followed by `hint`; a key given twice throws "... key 'k' given twice".
  static SpecText split(std::string_view text, std::string_view what, std::string_view hint = {});
};

/// `text` without leading and trailing spaces and tabs.
std::string_view trim_blanks(std::string_view text);

/// Strict conversions: the whole text must be the value (no trailing characters).
std::optional<long long> parse_integer(std::string_view text);
/// Finite numbers only.
std::optional<double> parse_number(std::string_view text);
/// on/true/1 and off/false/0.
std::optional<bool> parse_switch(std::string_view text);

/// `name:k1=v1,k2=v2` (just `name` without items): the canonical text, parsed back unchanged.
std::string format_spec(std::string_view name, const std::vector<std::pair<std::string, std::string>>& items);

/// "a, b, c" from anything with a `name` (or `key`) member, through `get`.
template <class Range, class Get>
std::string join_list(const Range& range, Get get) {
  std::string out;
  for (const auto& item : range) out.append(out.empty() ? "" : ", ").append(get(item));
  return out;
}

}  // namespace crumple
