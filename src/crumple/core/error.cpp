#include <crumple/core/error.hpp>

namespace crumple {

namespace {
std::string format_location(const std::string& file, const ParseError::Where& where) {
  // Appended piece by piece: `"literal" + std::to_string(...)` trips a GCC 12 -Wrestrict
  // false positive at -O2.
  std::string out = file;
  if (where.line) {
    out.append(":").append(std::to_string(*where.line));
  } else if (where.byte_offset) {
    out.append(": byte ").append(std::to_string(*where.byte_offset));
  }
  return out;
}
}  // namespace

ParseError::ParseError(std::string file, Where where, const std::string& message)
    : Error(format_location(file, where) + ": " + message),
      file_(std::move(file)),
      where_(where),
      message_(message) {}

namespace detail {
void throw_precondition(const char* condition, const std::string& message, const char* file,
                        int line) {
  throw PreconditionError(message + " [check `" + condition + "` failed at " + file + ":" +
                          std::to_string(line) + "]");
}
}  // namespace detail

}  // namespace crumple
