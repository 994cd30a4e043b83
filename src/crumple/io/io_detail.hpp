#pragma once
/// \file
/// Private helpers shared by the mesh readers and writers of crumple::io (not part of the API):
/// whole-file reading, locale-independent number parsing and printing, a line reader and a
/// token splitter for the text formats, and the error helpers every reader uses.

#include <crumple/core/error.hpp>
#include <crumple/core/types.hpp>

#include <cstdint>
#include <filesystem>
#include <optional>
#include <span>
#include <string>
#include <string_view>

namespace crumple::io::detail {

/// The whole file as bytes. Throws `ParseError` naming the file (and the system's reason) when
/// it is missing, a directory, or unreadable.
std::string read_whole_file(const std::filesystem::path& path);

/// Throws `ParseError` for `path` at a 1-based line.
[[noreturn]] void fail_at_line(const std::filesystem::path& path, std::int64_t line,
                               const std::string& message);
/// Throws `ParseError` for `path` at a byte offset from the start of the file.
[[noreturn]] void fail_at_byte(const std::filesystem::path& path, std::int64_t offset,
                               const std::string& message);
/// Throws `ParseError` for `path` with no location.
[[noreturn]] void fail_in_file(const std::filesystem::path& path, const std::string& message);

/// A token as it may appear in a message: single-quoted, at most 40 characters, bytes outside
/// printable ASCII written as `\xNN`.
std::string quote(std::string_view token);

/// Parses a whole token as a double (decimal or scientific notation, optional leading '+',
/// "inf"/"nan" accepted so that callers can report them as non-finite). Underflow gives the
/// nearest representable value (possibly 0); overflow gives +-infinity. Empty optional when the
/// token is not entirely a number.
std::optional<double> to_double(std::string_view token);
/// Parses a whole token as a decimal integer (optional leading '+'); empty on anything else,
/// including overflow of 64 bits.
std::optional<std::int64_t> to_int(std::string_view token);

/// Appends the shortest decimal text that reads back as exactly `value` (std::to_chars).
void append_double(std::string& out, double value);
void append_int(std::string& out, std::int64_t value);

/// Blank characters inside a line: space, tab, CR, VT, FF.
constexpr bool is_blank(char c) {
  return c == ' ' || c == '\t' || c == '\r' || c == '\v' || c == '\f';
}

/// Splits a string into tokens separated by blanks (and by any of `extra_separators`).
class Tokens {
 public:
  explicit Tokens(std::string_view text, std::string_view extra_separators = {})
      : text_(text), extra_(extra_separators) {}
  /// Next token, or an empty optional at the end.
  std::optional<std::string_view> next();
  /// True when only separators remain.
  bool at_end();

 private:
  bool is_separator(char c) const {
    return is_blank(c) || c == '\n' || extra_.find(c) != std::string_view::npos;
  }
  void skip_separators();
  std::string_view text_;
  std::string_view extra_;
  std::size_t pos_ = 0;
};

/// Iterates over the lines of a text (split at '\n'; a trailing '\r' is left in the line and is
/// a blank for `Tokens`). With `backslash_continuation`, a line whose last non-blank character
/// is '\' is joined with the next one (the backslash replaced by a space), and `line_number()`
/// is the first physical line of the joined line.
class LineReader {
 public:
  explicit LineReader(std::string_view text, bool backslash_continuation = false)
      : text_(text), continuation_(backslash_continuation) {}
  /// Next logical line, or an empty optional at the end of the text. The view stays valid until
  /// the next call.
  std::optional<std::string_view> next();
  /// 1-based number of the (first physical) line last returned; 0 before the first call.
  std::int64_t line_number() const { return line_number_; }
  /// Number of physical lines read so far.
  std::int64_t lines_read() const { return lines_read_; }

 private:
  std::optional<std::string_view> next_physical();
  std::string_view text_;
  bool continuation_;
  std::size_t pos_ = 0;
  std::int64_t line_number_ = 0;
  std::int64_t lines_read_ = 0;
  std::string joined_;
};

/// The part of a line before the first `marker` (the whole line when there is none).
std::string_view strip_comment(std::string_view line, char marker);

/// 1-based line number of a byte offset in a text.
std::int64_t line_of_offset(std::string_view text, std::size_t offset);

/// What is wrong with a triangle whose ids are not all different, with ids in the file's own
/// numbering (`base` added: 1 for OBJ, 0 otherwise), e.g. "triangle 1 1 2 repeats vertex 1
/// (a face needs distinct vertices)"; empty when the three ids differ. Every reader reports it
/// at the face's own line or byte, which `TriMesh::create` could not.
std::optional<std::string> repeated_vertex(const Face& t, std::int64_t base);

/// Checks the arguments of a mesh writer with `CRUMPLE_CHECK`: finite coordinates, face ids in
/// [0, #V), and counts that fit `Index`.
void check_mesh_for_writing(PositionsView positions, std::span<const Face> faces);

/// Appends one line `PREFIXx y z` per position (shortest exact decimals).
void append_position_lines(std::string& out, std::string_view prefix, PositionsView positions);
/// Appends one line `PREFIXa b c` per face, each id plus `id_offset` (1 for OBJ).
void append_face_lines(std::string& out, std::string_view prefix, std::span<const Face> faces,
                       std::int64_t id_offset);
/// Writes `content` to `path` atomically (see write_file_atomically).
void write_string_atomically(const std::filesystem::path& path, const std::string& content,
                             bool binary = false);

}  // namespace crumple::io::detail
