#pragma once
/// \file
/// The `NAME[:key=value,...]` syntax shared by method specs (`detect/method.hpp`) and scene
/// specs (`sim/scene.hpp`): splitting, trimming, setting keys checked against the owner's
/// table (`set_spec_key`), typed values and the canonical text. Each owner supplies only its
/// table of names and keys.

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

/// The `key=value` items of a spec, in the order they were first set.
using SpecItems = std::vector<std::pair<std::string, std::string>>;

/// `name:k1=v1,k2=v2` (just `name` without items): the canonical text, parsed back unchanged.
std::string format_spec(std::string_view name, const SpecItems& items);

/// "a, b, c" from anything with a `name` (or `key`) member, through `get`.
template <class Range, class Get>
std::string join_list(const Range& range, Get get) {
  std::string out;
  for (const auto& item : range) out.append(out.empty() ? "" : ", ").append(get(item));
  return out;
}

/// The value set for `key`, or null.
const std::string* find_spec_value(const SpecItems& items, std::string_view key);

/// Throws `InputError` "<owner>: unknown key '<key>' (valid keys: <valid>)"; `valid` empty
/// reads "none".
[[noreturn]] void throw_unknown_spec_key(std::string_view owner, std::string_view key, const std::string& valid);

/// The one key-setting routine of method and scene specs: checks `key` against `table` (any
/// range of entries with a `key` member, the owner's table of keys), then replaces its value in
/// `items` or appends it. An unknown key throws `InputError` naming `owner` (e.g. "method
/// kdop", "scene 'hanging-cloth'") and listing the table's keys.
template <class Table>
void set_spec_key(SpecItems& items, const Table& table, std::string key, std::string value,
                  std::string_view owner) {
  bool known = false;
  for (const auto& entry : table) known = known || entry.key == key;
  if (!known) throw_unknown_spec_key(owner, key, join_list(table, [](const auto& e) { return std::string(e.key); }));
  for (auto& [k, v] : items) {
    if (k == key) {
      v = std::move(value);
      return;
    }
  }
  items.emplace_back(std::move(key), std::move(value));
}

}  // namespace crumple
