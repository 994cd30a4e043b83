// The body of an ascii PLY file, token by token with line numbers; counts are checked against the
// bytes left before anything is allocated (ply_detail.hpp).

#include <crumple/io/io_detail.hpp>
#include <crumple/io/ply_detail.hpp>

#include <limits>
#include <string>

namespace crumple::io::detail {

namespace {

class AsciiBody {
 public:
  AsciiBody(const std::filesystem::path& path, std::string_view bytes, const PlyHeader& header)
      : path_(path), text_(bytes), pos_(header.body_offset), line_(header.body_first_line),
        header_(header) {}

  MeshData read() {
    check_sizes();
    MeshData mesh;
    for (const PlyElement& e : header_.elements) {
      switch (e.role) {
        case PlyRole::Vertex: read_vertices(e, mesh.positions); break;
        case PlyRole::Face: read_faces(e, mesh.faces); break;
        case PlyRole::Skip:
          for (std::uint64_t i = 0; i < e.count && !e.properties.empty(); ++i) {
            for (const PlyProperty& p : e.properties) skip_property(e, i, p);
          }
          break;
      }
    }
    if (next_token()) {
      fail_at_line(path_, line_, "unexpected " + quote(token_) + " after the last element");
    }
    return mesh;
  }

 private:
  void check_sizes() const {
    // n tokens need at least 2n-1 bytes (one character each, separated).
    const std::uint64_t body = text_.size() - pos_;
    std::uint64_t needed = 0;
    for (const PlyElement& e : header_.elements) {
      if (e.min_tokens == 0) continue;
      const std::uint64_t max_count = (body + 1 - needed) / (2 * e.min_tokens);
      if (e.count > max_count) {
        fail_at_line(path_, e.header_line,
                     "the header declares " + std::to_string(e.count) + " " + quote(e.name) +
                         " elements of at least " + std::to_string(e.min_tokens) +
                         (e.min_tokens == 1 ? " value" : " values") +
                         " each, which cannot fit in the " + std::to_string(body) +
                         " bytes after the header (file truncated or header corrupt)");
      }
      needed += e.count * 2 * e.min_tokens;
    }
  }

  // Advances to the next token; false at the end of the text.
  bool next_token() {
    while (pos_ < text_.size()) {
      const char c = text_[pos_];
      if (c == '\n') {
        ++line_;
      } else if (!detail::is_blank(c)) {
        break;
      }
      ++pos_;
    }
    if (pos_ >= text_.size()) return false;
    const std::size_t start = pos_;
    while (pos_ < text_.size() && text_[pos_] != '\n' && !detail::is_blank(text_[pos_])) ++pos_;
    token_ = text_.substr(start, pos_ - start);
    return true;
  }

  void expect_token(const PlyElement& e, std::uint64_t i, const PlyProperty& p) {
    if (!next_token()) {
      // At the end of the text: name its last line (not the empty one after a final newline).
      const std::int64_t last_line =
          std::max<std::int64_t>(1, line_ - (text_.ends_with('\n') ? 1 : 0));
      fail_at_line(path_, last_line,
                   "unexpected end of file: expected property " + quote(p.name) + " of " +
                       quote(e.name) + " " + std::to_string(i) + " (of " + std::to_string(e.count) + ")");
    }
  }

  [[noreturn]] void fail_value(const PlyElement& e, std::uint64_t i, const PlyProperty& p,
                               const char* expected) const {
    fail_at_line(path_, line_,
                 std::string("expected ") + expected + " for property " + quote(p.name) + " of " +
                     quote(e.name) + " " + std::to_string(i) + ", found " + quote(token_));
  }

  double read_real(const PlyElement& e, std::uint64_t i, const PlyProperty& p) {
    expect_token(e, i, p);
    const auto value = detail::to_double(token_);
    if (!value) fail_value(e, i, p, "a number");
    return *value;
  }

  std::int64_t read_int(const PlyElement& e, std::uint64_t i, const PlyProperty& p) {
    expect_token(e, i, p);
    const auto value = detail::to_int(token_);
    if (!value) fail_value(e, i, p, "an integer");
    return *value;
  }

  std::int64_t read_list_count(const PlyElement& e, std::uint64_t i, const PlyProperty& p) {
    const std::int64_t n = read_int(e, i, p);
    if (n < 0) fail_value(e, i, p, "a non-negative list length");
    return n;
  }

  void skip_property(const PlyElement& e, std::uint64_t i, const PlyProperty& p) {
    if (!p.is_list) {
      read_real(e, i, p);
      return;
    }
    const std::int64_t n = read_list_count(e, i, p);
    for (std::int64_t k = 0; k < n; ++k) read_real(e, i, p);
  }

  void read_vertices(const PlyElement& e, Positions& positions) {
    positions.resize(e.count);  // checked against the file size by check_sizes
    for (std::uint64_t i = 0; i < e.count; ++i) {
      for (std::size_t p = 0; p < e.properties.size(); ++p) {
        const PlyProperty& prop = e.properties[p];
        const int axis = static_cast<int>(p) == e.xyz[0]   ? 0
                         : static_cast<int>(p) == e.xyz[1] ? 1
                         : static_cast<int>(p) == e.xyz[2] ? 2
                                                           : -1;
        if (axis < 0) {
          skip_property(e, i, prop);
          continue;
        }
        const double value = read_real(e, i, prop);
        if (!std::isfinite(value)) {
          fail_at_line(path_, line_, "vertex " + std::to_string(i) + " has a non-finite coordinate " +
                                         quote(token_));
        }
        positions[i][axis] = value;
      }
    }
  }

  void read_faces(const PlyElement& e, std::vector<Face>& faces) {
    const auto nv = static_cast<std::int64_t>(
        header_.elements[static_cast<std::size_t>(header_.vertex_element)].count);
    // Reserve no more triangles than the remaining text can hold ("3 0 1 2\n" per face).
    const std::uint64_t fit = (text_.size() - pos_) / 8;
    faces.reserve(faces.size() + static_cast<std::size_t>(std::min<std::uint64_t>(e.count, fit)));
    for (std::uint64_t i = 0; i < e.count; ++i) {
      for (std::size_t p = 0; p < e.properties.size(); ++p) {
        const PlyProperty& prop = e.properties[p];
        if (static_cast<int>(p) != e.xyz[0]) {
          skip_property(e, i, prop);
          continue;
        }
        const std::int64_t n = read_list_count(e, i, prop);
        if (n < 3) {
          fail_at_line(path_, line_, "face " + std::to_string(i) + " has " + std::to_string(n) +
                                         " vertices (at least 3 needed)");
        }
        Index first = 0;
        Index previous = 0;
        for (std::int64_t k = 0; k < n; ++k) {
          const std::int64_t id = read_int(e, i, prop);
          if (id < 0 || id >= nv) {
            fail_at_line(path_, line_,
                         "face " + std::to_string(i) + " has vertex index " + std::to_string(id) +
                             " outside [0, " + std::to_string(nv) + ")");
          }
          const auto v = static_cast<Index>(id);
          if (k == 0) {
            first = v;
          } else if (k >= 2) {
            if (faces.size() >= static_cast<std::size_t>(std::numeric_limits<Index>::max())) {
              fail_at_line(path_, line_, "too many triangles (at most 2^31-1)");
            }
            const Face t{first, previous, v};
            if (const auto problem = detail::repeated_vertex(t, 0)) {
              fail_at_line(path_, line_, "face " + std::to_string(i) + ": " + *problem);
            }
            faces.push_back(t);
          }
          previous = v;
        }
      }
    }
  }

  const std::filesystem::path& path_;
  std::string_view text_;
  std::size_t pos_;
  std::int64_t line_;
  const PlyHeader& header_;
  std::string_view token_;
};

}  // namespace

MeshData read_ply_ascii_body(const std::filesystem::path& path, std::string_view bytes, const PlyHeader& header) {
  return AsciiBody(path, bytes, header).read();
}

}  // namespace crumple::io::detail
