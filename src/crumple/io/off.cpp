// Object File Format (Geomview OFF), text only.

#include <crumple/core/atomic_file.hpp>
#include <crumple/io/io_detail.hpp>
#include <crumple/io/mesh_io.hpp>

#include <limits>
#include <ostream>

namespace crumple::io {

namespace {

using detail::fail_at_line;
using detail::quote;

// True for the header keywords [ST][C][N]OFF, whose extra per-vertex values are ignored.
bool is_off_keyword(std::string_view token) {
  for (const std::string_view prefix : {"ST", "C", "N"}) {
    if (token.starts_with(prefix)) token.remove_prefix(prefix.size());
  }
  return token == "OFF";
}

class OffParser {
 public:
  OffParser(const std::filesystem::path& path, std::string_view text)
      : path_(path), text_(text), lines_(text) {}

  MeshData parse() {
    auto line = next_content_line();
    if (!line) fail_at_line(path_, 1, "empty file: expected an 'OFF' header");
    detail::Tokens tokens(*line);
    const std::string_view first = *tokens.next();
    if (!is_off_keyword(first)) {
      if (first.ends_with("OFF")) {
        fail("unsupported OFF variant " + quote(first) +
             " (only 3D OFF, COFF, NOFF, CNOFF, STOFF are read)");
      }
      if (!detail::to_int(first)) fail("expected an 'OFF' header, found " + quote(first));
      tokens = detail::Tokens(*line);  // header keyword omitted: this line holds the counts
    } else if (tokens.at_end()) {
      line = next_content_line();
      if (!line) fail_eof("the counts line 'vertices faces edges'");
      tokens = detail::Tokens(*line);
    }
    const auto counts = read_counts(tokens);
    read_vertices(counts[0]);
    read_faces(counts[1]);
    if (next_content_line()) {
      fail("unexpected content after the last face (the header declares " +
           std::to_string(counts[1]) + " faces)");
    }
    return std::move(data_);
  }

 private:
  [[noreturn]] void fail(const std::string& message) const {
    fail_at_line(path_, lines_.line_number(), message);
  }
  [[noreturn]] void fail_eof(const std::string& expected) const {
    fail_at_line(path_, std::max<std::int64_t>(lines_.lines_read(), 1),
                 "unexpected end of file: expected " + expected);
  }

  // Next line with something other than blanks and comments.
  std::optional<std::string_view> next_content_line() {
    while (auto raw = lines_.next()) {
      const std::string_view line = detail::strip_comment(*raw, '#');
      if (!detail::Tokens(line).at_end()) return line;
    }
    return std::nullopt;
  }

  std::array<std::int64_t, 2> read_counts(detail::Tokens& tokens) {
    std::array<std::int64_t, 3> counts{0, 0, 0};
    std::size_t n = 0;
    while (auto token = tokens.next()) {
      const auto value = detail::to_int(*token);
      if (n == 3 || !value || *value < 0) {
        fail("expected the counts 'vertices faces edges' (non-negative integers), found " +
             quote(*token));
      }
      counts[n++] = *value;
    }
    if (n < 2) fail("expected the counts 'vertices faces edges', found " + std::to_string(n) + " numbers");
    // Each vertex line takes at least 6 bytes ("0 0 0\n") and each face line 8 ("3 0 1 2\n"):
    // reject impossible counts before reserving memory for them.
    const auto size = static_cast<std::int64_t>(text_.size());
    if (counts[0] > size / 6 || counts[1] > size / 8 ||
        counts[0] > std::numeric_limits<Index>::max()) {
      fail("the header declares " + std::to_string(counts[0]) + " vertices and " +
           std::to_string(counts[1]) + " faces, which cannot fit in a file of " +
           std::to_string(size) + " bytes");
    }
    return {counts[0], counts[1]};
  }

  void read_vertices(std::int64_t count) {
    data_.positions.reserve(static_cast<std::size_t>(count));
    for (std::int64_t v = 0; v < count; ++v) {
      const auto line = next_content_line();
      if (!line) {
        fail_eof("vertex " + std::to_string(v) + " of " + std::to_string(count));
      }
      detail::Tokens tokens(*line);
      Vec3 p;
      int n = 0;
      while (auto token = tokens.next()) {
        const auto value = detail::to_double(*token);
        if (!value) {
          fail("expected a number in vertex " + std::to_string(v) + ", found " + quote(*token));
        }
        if (n < 3) p[n] = *value;
        ++n;  // values after x y z (colours, normals, texture coordinates) are ignored
      }
      if (n < 3) {
        fail("expected 'x y z' for vertex " + std::to_string(v) + ", found " + std::to_string(n) +
             " numbers");
      }
      if (!p.allFinite()) fail("vertex " + std::to_string(v) + " has a non-finite coordinate");
      data_.positions.push_back(p);
    }
  }

  void read_faces(std::int64_t count) {
    const auto nv = static_cast<std::int64_t>(data_.positions.size());
    data_.faces.reserve(static_cast<std::size_t>(count));
    for (std::int64_t f = 0; f < count; ++f) {
      const auto line = next_content_line();
      if (!line) fail_eof("face " + std::to_string(f) + " of " + std::to_string(count));
      detail::Tokens tokens(*line);
      const std::string_view count_token = *tokens.next();
      const auto n = detail::to_int(count_token);
      if (!n) {
        fail("expected the vertex count of face " + std::to_string(f) + ", found " +
             quote(count_token));
      }
      if (*n < 3) {
        fail("face " + std::to_string(f) + " has " + std::to_string(*n) +
             " vertices (at least 3 needed)");
      }
      Index first = 0;
      Index previous = 0;
      for (std::int64_t k = 0; k < *n; ++k) {
        const auto token = tokens.next();
        if (!token) {
          fail("face " + std::to_string(f) + " declares " + std::to_string(*n) +
               " vertices but lists " + std::to_string(k));
        }
        const auto id = detail::to_int(*token);
        if (!id) {
          fail("expected a vertex index in face " + std::to_string(f) + ", found " + quote(*token));
        }
        if (*id < 0 || *id >= nv) {
          fail("face " + std::to_string(f) + " has vertex index " + std::to_string(*id) +
               " outside [0, " + std::to_string(nv) + ")");
        }
        const auto vertex = static_cast<Index>(*id);
        if (k == 0) {
          first = vertex;
        } else if (k >= 2) {
          if (data_.faces.size() >= static_cast<std::size_t>(std::numeric_limits<Index>::max())) {
            fail("too many triangles (at most 2^31-1)");
          }
          const Face t{first, previous, vertex};
          if (const auto problem = detail::repeated_vertex(t, 0)) {
            fail("face " + std::to_string(f) + ": " + *problem);
          }
          data_.faces.push_back(t);
        }
        previous = vertex;
      }
      // Anything after the indices is a face colour: it must be numeric, and is ignored.
      while (auto token = tokens.next()) {
        if (!detail::to_double(*token)) {
          fail("unexpected " + quote(*token) + " after the " + std::to_string(*n) +
               " vertex indices of face " + std::to_string(f));
        }
      }
    }
  }

  const std::filesystem::path& path_;
  std::string_view text_;
  detail::LineReader lines_;
  MeshData data_;
};

}  // namespace

MeshData read_off(const std::filesystem::path& path) {
  const std::string text = detail::read_whole_file(path);
  return OffParser(path, text).parse();
}

void write_off(const std::filesystem::path& path, PositionsView positions,
               std::span<const Face> faces) {
  detail::check_mesh_for_writing(positions, faces);
  std::string out;
  out.reserve(64 + positions.size() * 64 + faces.size() * 24);
  out += "OFF\n";
  detail::append_int(out, static_cast<std::int64_t>(positions.size()));
  out += ' ';
  detail::append_int(out, static_cast<std::int64_t>(faces.size()));
  out += " 0\n";
  detail::append_position_lines(out, "", positions);
  detail::append_face_lines(out, "3 ", faces, 0);
  detail::write_string_atomically(path, out);
}

}  // namespace crumple::io
