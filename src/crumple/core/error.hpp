#pragma once
/// \file
/// Errors in three tiers (STYLE.md §8):
///  - bad files and user input throw `ParseError` / `InputError`;
///  - API preconditions use `CRUMPLE_CHECK`, on by default, which throws `PreconditionError`
///    naming the source file and line;
///  - internal invariants use `CRUMPLE_ASSERT` (debug builds only).
/// The library never prints.

#include <cassert>
#include <cstdint>
#include <optional>
#include <stdexcept>
#include <string>

namespace crumple {

/// Base of every exception crumple throws.
class Error : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// Invalid user input that is not a file (a bad method spec, an invalid mesh passed to a factory).
class InputError : public Error {
 public:
  using Error::Error;
};

/// A file that cannot be read or written, or whose content is malformed.
/// `what()` reads `FILE:LINE: message` for text formats and `FILE: byte OFFSET: message` for binary.
class ParseError : public Error {
 public:
  /// Location of the problem: a 1-based line for text, a byte offset for binary, or neither.
  struct Where {
    std::optional<std::int64_t> line;
    std::optional<std::int64_t> byte_offset;
  };
  ParseError(std::string file, Where where, const std::string& message);

  const std::string& file() const noexcept { return file_; }
  std::optional<std::int64_t> line() const noexcept { return where_.line; }
  std::optional<std::int64_t> byte_offset() const noexcept { return where_.byte_offset; }
  /// The message without the location prefix.
  const std::string& message() const noexcept { return message_; }

 private:
  std::string file_;
  Where where_;
  std::string message_;
};

/// A violated API precondition (see `CRUMPLE_CHECK`).
class PreconditionError : public Error {
 public:
  using Error::Error;
};

namespace detail {
[[noreturn]] void throw_precondition(const char* condition, const std::string& message,
                                     const char* file, int line);
}  // namespace detail

}  // namespace crumple

/// Checks an API precondition; on failure throws `crumple::PreconditionError` with the
/// condition, the message, and the source file and line. On in every build type.
#define CRUMPLE_CHECK(cond, msg)                                                      \
  do {                                                                                \
    if (!(cond)) ::crumple::detail::throw_precondition(#cond, (msg), __FILE__, __LINE__); \
  } while (false)

/// Internal invariant, checked in debug builds only.
#define CRUMPLE_ASSERT(cond) assert(cond)
