// X3D (XML encoding): IndexedFaceSet, IndexedTriangleSet and the thesis' MassSpring node.

#include <crumple/io/x3d.hpp>

#include <crumple/core/atomic_file.hpp>
#include <crumple/core/error.hpp>
#include <crumple/io/io_detail.hpp>
#include <crumple/io/mesh_io.hpp>

#include <pugixml.hpp>

#include <cmath>
#include <cstring>
#include <limits>
#include <ostream>

namespace crumple::io {

namespace {

using detail::quote;

constexpr auto max_count = static_cast<std::size_t>(std::numeric_limits<Index>::max());

// An X3D document with the raw text kept for turning node offsets into line numbers.
class X3dDocument {
 public:
  explicit X3dDocument(const std::filesystem::path& path)
      : path_(path), text_(detail::read_whole_file(path)) {
    // X3D's XML encoding is UTF-8; parsing as such keeps pugixml's offsets equal to byte
    // offsets in `text_`, from which error lines are computed.
    const pugi::xml_parse_result result =
        document_.load_buffer(text_.data(), text_.size(), pugi::parse_default, pugi::encoding_utf8);
    if (!result) {
      const std::string message = std::string("malformed XML: ") + result.description();
      detail::fail_at_line(
          path_, detail::line_of_offset(text_, static_cast<std::size_t>(std::max<std::ptrdiff_t>(result.offset, 0))),
          message);
    }
    const pugi::xml_node root = document_.document_element();
    if (std::strcmp(root.name(), "X3D") != 0) {
      fail(root, std::string("not an X3D file: the root element is <") + root.name() +
                     ">, expected <X3D>");
    }
  }

  const pugi::xml_document& document() const { return document_; }

  /// Throws `ParseError` at the line of `node`'s start tag.
  [[noreturn]] void fail(pugi::xml_node node, const std::string& message) const {
    const std::ptrdiff_t offset = node ? node.offset_debug() : -1;
    if (offset >= 0) {
      detail::fail_at_line(path_, detail::line_of_offset(text_, static_cast<std::size_t>(offset)),
                           message);
    }
    detail::fail_in_file(path_, message);
  }

  /// First element named `name` in document order, or a null node.
  pugi::xml_node find_first(std::initializer_list<const char*> names) const {
    return document_.find_node([&](pugi::xml_node n) {
      if (n.type() != pugi::node_element) return false;
      for (const char* name : names) {
        if (std::strcmp(n.name(), name) == 0) return true;
      }
      return false;
    });
  }

  /// Follows `USE="name"` to the element with `DEF="name"`.
  pugi::xml_node resolve_use(pugi::xml_node node) const {
    const pugi::xml_attribute use = node.attribute("USE");
    if (!use) return node;
    const pugi::xml_node target = document_.find_node([&](pugi::xml_node n) {
      return n.type() == pugi::node_element && std::strcmp(n.attribute("DEF").value(), use.value()) == 0 &&
             std::strcmp(n.name(), node.name()) == 0;
    });
    if (!target) {
      fail(node, std::string("<") + node.name() + " USE=" + quote(use.value()) +
                     "> refers to no <" + node.name() + " DEF=...> element");
    }
    return target;
  }

  /// Numbers of an attribute (blank- or comma-separated); empty when the attribute is absent.
  /// Values must be finite, and non-negative when `non_negative`.
  std::vector<double> reals(pugi::xml_node node, const char* attribute, bool non_negative = false) const {
    std::vector<double> values;
    detail::Tokens tokens(node.attribute(attribute).value(), ",");
    while (auto token = tokens.next()) {
      const auto value = detail::to_double(*token);
      if (!value) {
        fail(node, where(node, attribute) + "value " + std::to_string(values.size()) + " is " +
                       quote(*token) + ", expected a number");
      }
      if (!std::isfinite(*value)) {
        fail(node, where(node, attribute) + "value " + std::to_string(values.size()) + " (" +
                       quote(*token) + ") is not finite");
      }
      if (non_negative && *value < 0) {
        fail(node, where(node, attribute) + "value " + std::to_string(values.size()) + " (" +
                       quote(*token) + ") is negative, expected a number >= 0");
      }
      values.push_back(*value);
    }
    return values;
  }

  /// Integers of an attribute; empty when the attribute is absent.
  std::vector<std::int64_t> integers(pugi::xml_node node, const char* attribute) const {
    std::vector<std::int64_t> values;
    detail::Tokens tokens(node.attribute(attribute).value(), ",");
    while (auto token = tokens.next()) {
      const auto value = detail::to_int(*token);
      if (!value) {
        fail(node, where(node, attribute) + "value " + std::to_string(values.size()) + " is " +
                       quote(*token) + ", expected an integer");
      }
      values.push_back(*value);
    }
    return values;
  }

  /// "<Node attribute>: " for messages.
  static std::string where(pugi::xml_node node, const char* attribute) {
    return std::string("<") + node.name() + " " + attribute + ">: ";
  }

 private:
  const std::filesystem::path& path_;
  std::string text_;
  pugi::xml_document document_;
};

// Groups a flat list of numbers into 3D vectors.
Positions to_vectors(const X3dDocument& doc, pugi::xml_node node, const char* attribute,
                     const std::vector<double>& values) {
  if (values.size() % 3 != 0) {
    doc.fail(node, X3dDocument::where(node, attribute) + "has " + std::to_string(values.size()) +
                       " numbers, expected x y z triples (a multiple of 3)");
  }
  if (values.size() / 3 > max_count) doc.fail(node, X3dDocument::where(node, attribute) + "too many values");
  Positions out(values.size() / 3);
  for (std::size_t i = 0; i < out.size(); ++i) out[i] = Vec3(values[3 * i], values[3 * i + 1], values[3 * i + 2]);
  return out;
}

// Vertex ids in [0, nv); `group` (2 or 3) ids per element; returns the flat list.
std::vector<Index> vertex_ids(const X3dDocument& doc, pugi::xml_node node, const char* attribute,
                              std::size_t group, std::size_t nv, const char* element_word) {
  const std::vector<std::int64_t> raw = doc.integers(node, attribute);
  if (raw.size() % group != 0) {
    doc.fail(node, X3dDocument::where(node, attribute) + "has " + std::to_string(raw.size()) +
                       " vertex ids, expected " + std::to_string(group) + " per " + element_word +
                       " (a multiple of " + std::to_string(group) + ")");
  }
  if (raw.size() / group > max_count) doc.fail(node, X3dDocument::where(node, attribute) + "too many values");
  std::vector<Index> ids(raw.size());
  for (std::size_t i = 0; i < raw.size(); ++i) {
    if (raw[i] < 0 || raw[i] >= static_cast<std::int64_t>(nv)) {
      doc.fail(node, X3dDocument::where(node, attribute) + element_word + " " +
                         std::to_string(i / group) + " has vertex id " + std::to_string(raw[i]) +
                         " outside [0, " + std::to_string(nv) + ")");
    }
    ids[i] = static_cast<Index>(raw[i]);
  }
  return ids;
}

// Applies the list rule: empty -> `fallback`, shorter -> repeat the last value, longer -> error.
template <class T>
std::vector<T> fill_list(const X3dDocument& doc, pugi::xml_node node, const char* attribute,
                         std::vector<T> given, std::size_t count, const T& fallback,
                         const char* element_word) {
  if (given.size() > count) {
    doc.fail(node, X3dDocument::where(node, attribute) + "has " + std::to_string(given.size()) +
                       " values but there are only " + std::to_string(count) + " " + element_word +
                       " (a list may be shorter, its last value is then repeated, but not longer)");
  }
  if (given.empty()) return std::vector<T>(count, fallback);
  const T last = given.back();
  given.resize(count, last);
  return given;
}

// The one child element named `name`, a null node when there is none; more than one is an error.
pugi::xml_node single_child(const X3dDocument& doc, pugi::xml_node parent, const char* name) {
  pugi::xml_node found;
  for (pugi::xml_node child : parent.children(name)) {
    if (found) {
      doc.fail(child, std::string("a second <") + name + "> in <" + parent.name() +
                          "> (expected at most one)");
    }
    found = child;
  }
  return found;
}

Positions read_coordinate(const X3dDocument& doc, pugi::xml_node face_set) {
  pugi::xml_node coordinate;
  for (pugi::xml_node child : face_set.children()) {
    if (std::strcmp(child.name(), "Coordinate") == 0 ||
        std::strcmp(child.name(), "CoordinateDouble") == 0) {
      coordinate = child;
      break;
    }
  }
  if (!coordinate) {
    doc.fail(face_set, std::string("<") + face_set.name() +
                           "> has no <Coordinate point=\"x y z, ...\"> child");
  }
  coordinate = doc.resolve_use(coordinate);
  if (!coordinate.attribute("point")) {
    doc.fail(coordinate, std::string("<") + coordinate.name() + "> has no 'point' attribute");
  }
  return to_vectors(doc, coordinate, "point", doc.reals(coordinate, "point"));
}

MeshData read_indexed_face_set(const X3dDocument& doc, pugi::xml_node node) {
  MeshData mesh;
  mesh.positions = read_coordinate(doc, node);
  const auto nv = static_cast<std::int64_t>(mesh.positions.size());
  const std::vector<std::int64_t> ids = doc.integers(node, "coordIndex");
  std::size_t polygon = 0;
  std::size_t corners = 0;
  Index first = 0;
  Index previous = 0;
  const auto close_polygon = [&] {
    if (corners < 3) {
      doc.fail(node, "<IndexedFaceSet coordIndex>: polygon " + std::to_string(polygon) + " has " +
                         std::to_string(corners) + " vertices (at least 3 needed before each -1)");
    }
    ++polygon;
    corners = 0;
  };
  for (std::size_t i = 0; i < ids.size(); ++i) {
    const std::int64_t id = ids[i];
    if (id == -1) {
      close_polygon();
      continue;
    }
    if (id < 0 || id >= nv) {
      doc.fail(node, "<IndexedFaceSet coordIndex>: value " + std::to_string(i) + " (polygon " +
                         std::to_string(polygon) + ") is " + std::to_string(id) +
                         ", expected a vertex id in [0, " + std::to_string(nv) + ") or -1");
    }
    const auto v = static_cast<Index>(id);
    if (corners == 0) {
      first = v;
    } else if (corners >= 2) {
      if (mesh.faces.size() >= max_count) doc.fail(node, "too many triangles");
      const Face t{first, previous, v};
      if (const auto problem = detail::repeated_vertex(t, 0)) {
        doc.fail(node, "<IndexedFaceSet coordIndex>: polygon " + std::to_string(polygon) + ": " + *problem);
      }
      mesh.faces.push_back(t);
    }
    previous = v;
    ++corners;
  }
  if (corners > 0) close_polygon();  // the final -1 is optional
  return mesh;
}

MeshData read_indexed_triangle_set(const X3dDocument& doc, pugi::xml_node node) {
  MeshData mesh;
  mesh.positions = read_coordinate(doc, node);
  const std::vector<Index> ids = vertex_ids(doc, node, "index", 3, mesh.positions.size(), "triangle");
  mesh.faces.resize(ids.size() / 3);
  for (std::size_t f = 0; f < mesh.faces.size(); ++f) {
    mesh.faces[f] = {ids[3 * f], ids[3 * f + 1], ids[3 * f + 2]};
    if (const auto problem = detail::repeated_vertex(mesh.faces[f], 0)) {
      doc.fail(node, "<IndexedTriangleSet index>: triangle " + std::to_string(f) + ": " + *problem);
    }
  }
  return mesh;
}

MassSpringData read_mass_spring_node(const X3dDocument& doc, pugi::xml_node node,
                                     const MassSpringDefaults& defaults) {
  MassSpringData data;
  const pugi::xml_node vertex = single_child(doc, node, "Vertex");
  if (!vertex) doc.fail(node, "<MassSpring> has no <Vertex point=\"x y z, ...\"> child");
  if (!vertex.attribute("point")) doc.fail(vertex, "<Vertex> has no 'point' attribute");
  data.positions = to_vectors(doc, vertex, "point", doc.reals(vertex, "point"));
  const std::size_t nv = data.positions.size();
  data.masses = fill_list(doc, vertex, "mass", doc.reals(vertex, "mass", true), nv, defaults.mass,
                          "vertices");
  data.velocities = fill_list(doc, vertex, "velocity",
                              to_vectors(doc, vertex, "velocity", doc.reals(vertex, "velocity")),
                              nv, Vec3(Vec3::Zero()), "vertices");

  if (const pugi::xml_node edge = single_child(doc, node, "Edge")) {
    const std::vector<Index> ids = vertex_ids(doc, edge, "vertex", 2, nv, "spring");
    const std::size_t ns = ids.size() / 2;
    data.springs.resize(ns);
    for (std::size_t s = 0; s < ns; ++s) {
      data.springs[s] = {ids[2 * s], ids[2 * s + 1]};
      if (ids[2 * s] == ids[2 * s + 1]) {
        doc.fail(edge, "<Edge vertex>: spring " + std::to_string(s) + " joins vertex " +
                           std::to_string(ids[2 * s]) + " to itself");
      }
    }
    data.stiffness = fill_list(doc, edge, "stiffness", doc.reals(edge, "stiffness", true), ns,
                               defaults.stiffness, "springs");
    data.damping_ratio = fill_list(doc, edge, "dampingRatio", doc.reals(edge, "dampingRatio", true),
                                   ns, defaults.damping_ratio, "springs");
    std::vector<double> lengths = doc.reals(edge, "length", true);
    if (lengths.empty()) {
      lengths.resize(ns);
      for (std::size_t s = 0; s < ns; ++s) {
        const Edge& e = data.springs[s];
        lengths[s] = (data.positions[static_cast<std::size_t>(e[1])] -
                      data.positions[static_cast<std::size_t>(e[0])])
                         .norm();
      }
    }
    data.rest_length = fill_list(doc, edge, "length", std::move(lengths), ns, 0.0, "springs");
  }

  if (const pugi::xml_node face = single_child(doc, node, "Face")) {
    const std::vector<Index> ids = vertex_ids(doc, face, "vertex", 3, nv, "triangle");
    data.faces.resize(ids.size() / 3);
    for (std::size_t f = 0; f < data.faces.size(); ++f) {
      data.faces[f] = {ids[3 * f], ids[3 * f + 1], ids[3 * f + 2]};
      if (const auto problem = detail::repeated_vertex(data.faces[f], 0)) {
        doc.fail(face, "<Face vertex>: triangle " + std::to_string(f) + ": " + *problem);
      }
    }
  }
  return data;
}

// ---------------------------------------------------------------------------------------------
// Writing

void append_vectors(std::string& out, PositionsView values, std::string_view indent) {
  for (std::size_t i = 0; i < values.size(); ++i) {
    out += '\n';
    out += indent;
    for (int a = 0; a < 3; ++a) {
      if (a) out += ' ';
      detail::append_double(out, values[i][a]);
    }
    if (i + 1 < values.size()) out += ',';
  }
}

void append_scalars(std::string& out, const std::vector<Scalar>& values) {
  for (std::size_t i = 0; i < values.size(); ++i) {
    if (i) out += ' ';
    detail::append_double(out, values[i]);
  }
}

template <std::size_t N>
void append_tuples(std::string& out, std::span<const std::array<Index, N>> tuples,
                   std::string_view indent, std::string_view terminator) {
  for (std::size_t i = 0; i < tuples.size(); ++i) {
    out += '\n';
    out += indent;
    for (std::size_t k = 0; k < N; ++k) {
      if (k) out += ' ';
      detail::append_int(out, tuples[i][k]);
    }
    if (i + 1 < tuples.size() || terminator == " -1") out += terminator;
  }
}

constexpr std::string_view x3d_prologue =
    "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n"
    "<X3D profile=\"Interchange\" version=\"3.3\">\n"
    "  <Scene>\n"
    "    <Shape>\n";
constexpr std::string_view x3d_epilogue =
    "    </Shape>\n"
    "  </Scene>\n"
    "</X3D>\n";

void write_text(const std::filesystem::path& path, const std::string& text) {
  detail::write_string_atomically(path, text);
}

}  // namespace

MeshData read_x3d(const std::filesystem::path& path) {
  const X3dDocument doc(path);
  const pugi::xml_node node = doc.find_first({"IndexedFaceSet", "IndexedTriangleSet", "MassSpring"});
  if (!node) {
    doc.fail(doc.document().document_element(),
             "no <IndexedFaceSet>, <IndexedTriangleSet> or <MassSpring> node in the file");
  }
  if (std::strcmp(node.name(), "IndexedFaceSet") == 0) return read_indexed_face_set(doc, node);
  if (std::strcmp(node.name(), "IndexedTriangleSet") == 0) return read_indexed_triangle_set(doc, node);
  MassSpringData data = read_mass_spring_node(doc, node, {});
  return MeshData{std::move(data.positions), std::move(data.faces)};
}

MassSpringData read_mass_spring(const std::filesystem::path& path, const MassSpringDefaults& defaults) {
  const X3dDocument doc(path);
  const pugi::xml_node node = doc.find_first({"MassSpring"});
  if (!node) doc.fail(doc.document().document_element(), "no <MassSpring> node in the file");
  return read_mass_spring_node(doc, node, defaults);
}

void write_x3d(const std::filesystem::path& path, PositionsView positions,
               std::span<const Face> faces) {
  detail::check_mesh_for_writing(positions, faces);
  std::string out;
  out.reserve(512 + positions.size() * 64 + faces.size() * 32);
  out += x3d_prologue;
  out += "      <IndexedFaceSet solid=\"false\" coordIndex=\"";
  append_tuples<3>(out, faces, "        ", " -1");
  out += "\">\n        <Coordinate point=\"";
  append_vectors(out, positions, "          ");
  out += "\"/>\n      </IndexedFaceSet>\n";
  out += x3d_epilogue;
  write_text(path, out);
}

void write_mass_spring(const std::filesystem::path& path, const MassSpringData& data) {
  const std::size_t nv = data.positions.size();
  const std::size_t ns = data.springs.size();
  CRUMPLE_CHECK(data.masses.size() == nv && data.velocities.size() == nv,
                "masses and velocities need one entry per vertex");
  CRUMPLE_CHECK(data.stiffness.size() == ns && data.damping_ratio.size() == ns &&
                    data.rest_length.size() == ns,
                "stiffness, damping_ratio and rest_length need one entry per spring");
  detail::check_mesh_for_writing(data.positions, data.faces);
  for (std::size_t v = 0; v < nv; ++v) {
    CRUMPLE_CHECK(std::isfinite(data.masses[v]) && data.masses[v] >= 0,
                  "vertex " + std::to_string(v) + " needs a finite mass >= 0");
    CRUMPLE_CHECK(data.velocities[v].allFinite(),
                  "vertex " + std::to_string(v) + " has a non-finite velocity");
  }
  for (std::size_t s = 0; s < ns; ++s) {
    const Edge& e = data.springs[s];
    CRUMPLE_CHECK(e[0] >= 0 && e[1] >= 0 && static_cast<std::size_t>(e[0]) < nv &&
                      static_cast<std::size_t>(e[1]) < nv && e[0] != e[1],
                  "spring " + std::to_string(s) + " needs two distinct vertex ids in [0, #V)");
    for (const Scalar value : {data.stiffness[s], data.damping_ratio[s], data.rest_length[s]}) {
      CRUMPLE_CHECK(std::isfinite(value) && value >= 0,
                    "spring " + std::to_string(s) +
                        " needs finite stiffness, damping ratio and rest length >= 0");
    }
  }

  std::string out;
  out.reserve(1024 + nv * 128 + ns * 96 + data.faces.size() * 32);
  out += x3d_prologue;
  out += "      <MassSpring>\n        <Vertex point=\"";
  append_vectors(out, data.positions, "          ");
  out += "\"\n          mass=\"";
  append_scalars(out, data.masses);
  out += "\"\n          velocity=\"";
  append_vectors(out, data.velocities, "          ");
  out += "\"/>\n        <Edge vertex=\"";
  append_tuples<2>(out, std::span<const Edge>(data.springs), "          ", ",");
  out += "\"\n          stiffness=\"";
  append_scalars(out, data.stiffness);
  out += "\"\n          dampingRatio=\"";
  append_scalars(out, data.damping_ratio);
  out += "\"\n          length=\"";
  append_scalars(out, data.rest_length);
  out += "\"/>\n        <Face vertex=\"";
  append_tuples<3>(out, std::span<const Face>(data.faces), "          ", ",");
  out += "\"/>\n      </MassSpring>\n";
  out += x3d_epilogue;
  write_text(path, out);
}

}  // namespace crumple::io
