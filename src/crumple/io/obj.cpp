// Wavefront OBJ: geometry statements `v` and `f` only.

#include <crumple/core/atomic_file.hpp>
#include <crumple/io/io_detail.hpp>
#include <crumple/io/mesh_io.hpp>

#include <algorithm>
#include <array>
#include <iterator>
#include <limits>
#include <ostream>

namespace crumple::io {

namespace {

using detail::fail_at_line;
using detail::quote;

// Statements that are valid OBJ but carry nothing a triangle mesh needs.
constexpr std::string_view ignored_keywords[] = {
    // texture and normal data, grouping, smoothing, materials
    "vt", "vn", "vp", "o", "g", "s", "mg", "usemtl", "mtllib", "usemap", "maplib",
    // line and point elements
    "l", "p",
    // free-form curves and surfaces
    "cstype", "deg", "bmat", "step", "curv", "curv2", "surf", "parm", "trim", "hole", "scrv", "sp",
    "end", "con", "res",
    // display and rendering attributes
    "lod", "c_interp", "d_interp", "shadow_obj", "trace_obj", "ctech", "stech", "bevel",
    // general statements
    "call", "csh"};

bool is_ignored_keyword(std::string_view keyword) {
  return std::ranges::find(ignored_keywords, keyword) != std::end(ignored_keywords);
}

class ObjParser {
 public:
  ObjParser(const std::filesystem::path& path, std::string_view text)
      : path_(path), lines_(text, /*backslash_continuation=*/true) {}

  MeshData parse() {
    while (auto raw = lines_.next()) {
      const std::string_view line = detail::strip_comment(*raw, '#');
      detail::Tokens tokens(line);
      const auto keyword = tokens.next();
      if (!keyword) continue;
      if (*keyword == "v") {
        parse_vertex(tokens);
      } else if (*keyword == "f") {
        parse_face(tokens);
      } else if (!is_ignored_keyword(*keyword)) {
        fail("unknown statement " + quote(*keyword) +
             " (expected v, f or another OBJ keyword such as vt, vn, o, g, s, usemtl)");
      }
    }
    // Forward references, now that every vertex is known: report the first one out of range.
    const auto count = static_cast<std::int64_t>(data_.positions.size());
    for (const ForwardReference& ref : forward_) {
      if (ref.id >= count) {
        fail_at_line(path_, ref.line,
                     "vertex index " + std::to_string(ref.id + 1) +
                         " is out of range: the file has " + std::to_string(count) + " vertices");
      }
    }
    return std::move(data_);
  }

 private:
  [[noreturn]] void fail(const std::string& message) const {
    fail_at_line(path_, lines_.line_number(), message);
  }

  void parse_vertex(detail::Tokens& tokens) {
    std::array<double, 7> values{};
    std::size_t n = 0;
    while (auto token = tokens.next()) {
      if (n == values.size()) fail("too many values after 'v' (expected 'v x y z [w]')");
      const auto value = detail::to_double(*token);
      if (!value) fail("expected a number in 'v x y z [w]', found " + quote(*token));
      values[n++] = *value;
    }
    if (n != 3 && n != 4 && n != 6 && n != 7) {
      fail("expected 'v x y z [w]' (3 or 4 numbers, or 6 or 7 with an RGB colour), found " +
           std::to_string(n) + " numbers");
    }
    const Vec3 p(values[0], values[1], values[2]);
    if (!p.allFinite()) fail("vertex " + std::to_string(data_.positions.size() + 1) +
                             " has a non-finite coordinate");
    if (data_.positions.size() >= static_cast<std::size_t>(std::numeric_limits<Index>::max())) {
      fail("too many vertices (at most 2^31-1)");
    }
    data_.positions.push_back(p);
  }

  // One `i`, `i/vt`, `i//vn` or `i/vt/vn` reference; returns the 0-based vertex id.
  Index parse_reference(std::string_view ref) {
    const std::size_t slash = ref.find('/');
    const std::string_view vertex_part = ref.substr(0, slash);
    if (slash != std::string_view::npos) {
      const std::string_view rest = ref.substr(slash + 1);
      const std::size_t slash2 = rest.find('/');
      const std::string_view texture = rest.substr(0, slash2);
      const std::string_view normal =
          slash2 == std::string_view::npos ? std::string_view{} : rest.substr(slash2 + 1);
      const bool ok_texture = texture.empty() ? slash2 != std::string_view::npos
                                              : detail::to_int(texture).value_or(0) != 0;
      const bool ok_normal =
          slash2 == std::string_view::npos || detail::to_int(normal).value_or(0) != 0;
      if (!ok_texture || !ok_normal || normal.find('/') != std::string_view::npos) {
        fail("malformed face vertex " + quote(ref) + " (expected i, i/vt, i//vn or i/vt/vn)");
      }
    }
    const auto index = detail::to_int(vertex_part);
    if (!index) {
      fail("malformed face vertex " + quote(ref) + " (expected i, i/vt, i//vn or i/vt/vn)");
    }
    const auto count = static_cast<std::int64_t>(data_.positions.size());
    if (*index == 0) fail("vertex index 0 in a face (OBJ indices start at 1)");
    if (*index < 0) {
      const std::int64_t id = count + *index;
      if (id < 0) {
        fail("relative vertex index " + std::to_string(*index) + " reaches before the first vertex (" +
             std::to_string(count) + " vertices so far)");
      }
      return static_cast<Index>(id);
    }
    const std::int64_t id = *index - 1;
    if (id >= std::numeric_limits<Index>::max()) {
      fail("vertex index " + std::to_string(*index) + " is out of range");
    }
    // Forward references are checked once all vertices are known (one entry per line suffices:
    // the largest id of the line).
    if (id >= count) {
      if (!forward_.empty() && forward_.back().line == lines_.line_number()) {
        forward_.back().id = std::max(forward_.back().id, id);
      } else {
        forward_.push_back({lines_.line_number(), id});
      }
    }
    return static_cast<Index>(id);
  }

  void parse_face(detail::Tokens& tokens) {
    std::size_t n = 0;
    Index first = 0;
    Index previous = 0;
    while (auto token = tokens.next()) {
      const Index id = parse_reference(*token);
      if (n == 0) {
        first = id;
      } else if (n >= 2) {
        if (data_.faces.size() >= static_cast<std::size_t>(std::numeric_limits<Index>::max())) {
          fail("too many faces (at most 2^31-1)");
        }
        const Face t{first, previous, id};
        if (const auto problem = detail::repeated_vertex(t, 1)) fail(*problem);
        data_.faces.push_back(t);
      }
      previous = id;
      ++n;
    }
    if (n < 3) {
      fail("a face needs at least 3 vertices, found " + std::to_string(n));
    }
  }

  const std::filesystem::path& path_;
  detail::LineReader lines_;
  MeshData data_;
  struct ForwardReference {
    std::int64_t line;
    std::int64_t id;  // 0-based, not yet defined when read
  };
  std::vector<ForwardReference> forward_;
};

}  // namespace

MeshData read_obj(const std::filesystem::path& path) {
  const std::string text = detail::read_whole_file(path);
  return ObjParser(path, text).parse();
}

void write_obj(const std::filesystem::path& path, PositionsView positions,
               std::span<const Face> faces) {
  detail::check_mesh_for_writing(positions, faces);
  std::string out;
  out.reserve(64 + positions.size() * 64 + faces.size() * 24);
  out += "# written by crumple: ";
  detail::append_int(out, static_cast<std::int64_t>(positions.size()));
  out += " vertices, ";
  detail::append_int(out, static_cast<std::int64_t>(faces.size()));
  out += " triangles\n";
  detail::append_position_lines(out, "v ", positions);
  detail::append_face_lines(out, "f ", faces, 1);
  detail::write_string_atomically(path, out);
}

}  // namespace crumple::io
