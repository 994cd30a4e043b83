#pragma once
/// \file
/// A minimal JSON object writer for machine-readable output (one object per line).

#include <string>
#include <string_view>

namespace crumple {

/// Escapes a string for a JSON string literal (without the surrounding quotes).
std::string json_escape(std::string_view text);

/// Builds one JSON object, field by field: `JsonObject().add("a", 1).add("b", "x").str()`.
/// Numbers print in the shortest form that reads back exactly; non-finite ones as null.
class JsonObject {
 public:
  JsonObject& add(std::string_view key, double value);
  JsonObject& add(std::string_view key, long long value);
  JsonObject& add(std::string_view key, int value) { return add(key, static_cast<long long>(value)); }
  JsonObject& add(std::string_view key, std::size_t value) {
    return add(key, static_cast<long long>(value));
  }
  JsonObject& add(std::string_view key, bool value);
  JsonObject& add(std::string_view key, std::string_view value);
  JsonObject& add(std::string_view key, const char* value) { return add(key, std::string_view(value)); }
  /// Adds a nested object or array given as already-formatted JSON text.
  JsonObject& add_raw(std::string_view key, std::string_view json);
  std::string str() const { return body_ + "}"; }

 private:
  void key(std::string_view name);
  std::string body_ = "{";
};

/// Formats a double as JSON (the shortest text that reads back exactly; null when not finite).
std::string json_number(double value);

}  // namespace crumple
