#include <crumple/core/spec_text.hpp>

#include <crumple/core/error.hpp>

#include <charconv>
#include <cmath>

namespace crumple {

std::string_view trim_blanks(std::string_view s) {
  while (!s.empty() && (s.front() == ' ' || s.front() == '\t')) s.remove_prefix(1);
  while (!s.empty() && (s.back() == ' ' || s.back() == '\t')) s.remove_suffix(1);
  return s;
}

SpecText SpecText::split(std::string_view text, std::string_view what, std::string_view hint) {
  text = trim_blanks(text);
  const std::size_t colon = text.find(':');
  SpecText spec;
  spec.name = std::string(trim_blanks(text.substr(0, colon)));
  if (colon == std::string_view::npos) return spec;
  std::string_view rest = text.substr(colon + 1);
  const auto fail = [&](const std::string& message) {
    std::string full = std::string(what).append(" '").append(text).append("': ").append(message);
    if (!hint.empty()) full.append(" (").append(hint).append(")");
    throw InputError(full);
  };
  while (!rest.empty()) {
    const std::size_t comma = rest.find(',');
    const std::string_view item = trim_blanks(rest.substr(0, comma));
    rest = comma == std::string_view::npos ? std::string_view() : rest.substr(comma + 1);
    if (item.empty()) continue;
    const std::size_t eq = item.find('=');
    if (eq == std::string_view::npos || trim_blanks(item.substr(0, eq)).empty()) {
      fail(std::string("expected key=value, got '").append(item).append("'"));
    }
    std::string key(trim_blanks(item.substr(0, eq)));
    for (const auto& [k, v] : spec.items) {
      if (k == key) fail("key '" + key + "' given twice");
    }
    spec.items.emplace_back(std::move(key), std::string(trim_blanks(item.substr(eq + 1))));
  }
  return spec;
}

std::optional<long long> parse_integer(std::string_view text) {
  long long out = 0;
  const auto [ptr, ec] = std::from_chars(text.data(), text.data() + text.size(), out);
  if (ec != std::errc() || ptr != text.data() + text.size()) return std::nullopt;
  return out;
}

std::optional<double> parse_number(std::string_view text) {
  double out = 0;
  const auto [ptr, ec] = std::from_chars(text.data(), text.data() + text.size(), out);
  if (ec != std::errc() || ptr != text.data() + text.size() || !std::isfinite(out)) return std::nullopt;
  return out;
}

std::optional<bool> parse_switch(std::string_view text) {
  if (text == "on" || text == "true" || text == "1") return true;
  if (text == "off" || text == "false" || text == "0") return false;
  return std::nullopt;
}

const std::string* find_spec_value(const SpecItems& items, std::string_view key) {
  for (const auto& [k, v] : items) {
    if (k == key) return &v;
  }
  return nullptr;
}

void throw_unknown_spec_key(std::string_view owner, std::string_view key, const std::string& valid) {
  throw InputError(std::string(owner) + ": unknown key '" + std::string(key) + "' (valid keys: " +
                   (valid.empty() ? std::string("none") : valid) + ")");
}

std::string format_spec(std::string_view name, const SpecItems& items) {
  std::string out(name);
  for (std::size_t i = 0; i < items.size(); ++i) {
    out.append(i == 0 ? ":" : ",").append(items[i].first).append("=").append(items[i].second);
  }
  return out;
}

}  // namespace crumple
