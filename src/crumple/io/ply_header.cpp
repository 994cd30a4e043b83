// The PLY header: format line, elements, properties (scalar and list types), and which element
// holds the vertices and which the faces (ply_detail.hpp).

#include <crumple/io/io_detail.hpp>
#include <crumple/io/ply_detail.hpp>

#include <optional>
#include <string>
#include <string_view>
#include <utility>

namespace crumple::io::detail {

namespace {

std::optional<PlyType> parse_type(std::string_view name) {
  struct Entry {
    std::string_view name;
    PlyType type;
  };
  static constexpr Entry table[] = {
      {"char", PlyType::Int8},     {"int8", PlyType::Int8},       {"uchar", PlyType::UInt8},
      {"uint8", PlyType::UInt8},   {"short", PlyType::Int16},     {"int16", PlyType::Int16},
      {"ushort", PlyType::UInt16}, {"uint16", PlyType::UInt16},   {"int", PlyType::Int32},
      {"int32", PlyType::Int32},   {"uint", PlyType::UInt32},     {"uint32", PlyType::UInt32},
      {"float", PlyType::Float32}, {"float32", PlyType::Float32}, {"double", PlyType::Float64},
      {"float64", PlyType::Float64}};
  for (const Entry& e : table) {
    if (e.name == name) return e.type;
  }
  return std::nullopt;
}

bool is_printable_header_line(std::string_view line) {
  for (const char c : line) {
    const auto u = static_cast<unsigned char>(c);
    if (u < 0x20 && c != '\t' && c != '\r') return false;
    if (u == 0x7f) return false;
  }
  return true;
}

class HeaderParser {
 public:
  HeaderParser(const std::filesystem::path& path, std::string_view bytes)
      : path_(path), bytes_(bytes), lines_(bytes) {}

  PlyHeader parse() {
    read_lines();
    assign_roles();
    return std::move(header_);
  }

 private:
  [[noreturn]] void fail(const std::string& message) const {
    fail_at_line(path_, std::max<std::int64_t>(lines_.line_number(), 1), message);
  }

  void read_lines() {
    auto magic = lines_.next();
    std::string_view first = magic.value_or(std::string_view{});
    if (first.ends_with('\r')) first.remove_suffix(1);
    if (first != "ply") fail("not a PLY file: the first line must be 'ply'");
    std::size_t consumed = magic->size() + 1;
    while (auto line = lines_.next()) {
      consumed += line->size() + 1;
      if (!is_printable_header_line(*line)) {
        fail("unexpected binary data in the PLY header (is the 'end_header' line missing?)");
      }
      detail::Tokens tokens(*line);
      const auto keyword = tokens.next();
      if (!keyword || *keyword == "comment" || *keyword == "obj_info") continue;
      if (*keyword == "end_header") {
        if (!tokens.at_end()) fail("unexpected text after 'end_header'");
        if (!have_format_) fail("the PLY header has no 'format' line");
        header_.body_offset = std::min(consumed, bytes_.size());
        header_.body_first_line = lines_.line_number() + 1;
        return;
      }
      if (*keyword == "format") {
        read_format(tokens);
      } else if (*keyword == "element") {
        read_element(tokens);
      } else if (*keyword == "property") {
        read_property(tokens);
      } else {
        fail("unexpected " + quote(*keyword) +
             " in the PLY header (expected format, comment, obj_info, element, property or "
             "end_header)");
      }
    }
    fail_at_line(path_, std::max<std::int64_t>(lines_.lines_read(), 1),
                 "the PLY header has no 'end_header' line");
  }

  void read_format(detail::Tokens& tokens) {
    if (have_format_) fail("a second 'format' line");
    const auto encoding = tokens.next();
    const auto version = tokens.next();
    if (!encoding || !version || !tokens.at_end() ||
        (*encoding != "ascii" && *encoding != "binary_little_endian" &&
         *encoding != "binary_big_endian")) {
      fail("expected 'format ascii|binary_little_endian|binary_big_endian 1.0'");
    }
    if (*version != "1.0" && *version != "1") {
      fail("unsupported PLY version " + quote(*version) + " (expected 1.0)");
    }
    header_.encoding = *encoding == "ascii"                  ? PlyEncoding::Ascii
                       : *encoding == "binary_little_endian" ? PlyEncoding::BinaryLittleEndian
                                                             : PlyEncoding::BinaryBigEndian;
    have_format_ = true;
  }

  void read_element(detail::Tokens& tokens) {
    if (!have_format_) fail("'element' before the 'format' line");
    const auto name = tokens.next();
    const auto count = tokens.next();
    if (!name || !count || !tokens.at_end()) fail("expected 'element <name> <count>'");
    const auto parsed = detail::to_int(*count);
    if (!parsed || *parsed < 0) {
      fail("the count of element " + quote(*name) + " must be a non-negative integer, found " +
           quote(*count));
    }
    for (const PlyElement& e : header_.elements) {
      if (e.name == *name) fail("a second element named " + quote(*name));
    }
    PlyElement element;
    element.name = std::string(*name);
    element.count = static_cast<std::uint64_t>(*parsed);
    element.header_line = lines_.line_number();
    header_.elements.push_back(std::move(element));
  }

  PlyType read_type(std::string_view name) const {
    const auto type = parse_type(name);
    if (!type) {
      fail("unknown type " + quote(name) +
           " (expected char, uchar, short, ushort, int, uint, float, double or int8 ... float64)");
    }
    return *type;
  }

  void read_property(detail::Tokens& tokens) {
    if (header_.elements.empty()) fail("'property' before any 'element'");
    PlyElement& element = header_.elements.back();
    PlyProperty property;
    const auto type = tokens.next();
    if (type && *type == "list") {
      const auto count_type = tokens.next();
      const auto item_type = tokens.next();
      const auto name = tokens.next();
      if (!count_type || !item_type || !name || !tokens.at_end()) {
        fail("expected 'property list <count type> <item type> <name>'");
      }
      property.is_list = true;
      property.count_type = read_type(*count_type);
      property.type = read_type(*item_type);
      property.name = std::string(*name);
      if (!is_integer(property.count_type)) {
        fail("the count type of list " + quote(*name) + " must be an integer type");
      }
    } else {
      const auto name = tokens.next();
      if (!type || !name || !tokens.at_end()) {
        fail("expected 'property <type> <name>' or 'property list <count type> <item type> <name>'");
      }
      property.type = read_type(*type);
      property.name = std::string(*name);
    }
    for (const PlyProperty& p : element.properties) {
      if (p.name == property.name) {
        fail("a second property named " + quote(property.name) + " in element " +
             quote(element.name));
      }
    }
    element.properties.push_back(std::move(property));
  }

  // Roles, checks of the vertex and face elements, and the minimum encoded size of each element.
  void assign_roles() {
    for (std::size_t i = 0; i < header_.elements.size(); ++i) {
      PlyElement& e = header_.elements[i];
      if (e.name == "vertex") {
        e.role = PlyRole::Vertex;
        header_.vertex_element = static_cast<int>(i);
        find_xyz(e);
        if (e.count > static_cast<std::uint64_t>(std::numeric_limits<Index>::max())) {
          fail_at_line(path_, e.header_line,
                       "too many vertices: " + std::to_string(e.count) + " (at most 2^31-1)");
        }
      } else if (e.name == "face") {
        e.role = PlyRole::Face;
        find_index_list(e);
      } else if (e.name == "tristrips" || e.name == "triangle_strips") {
        fail_at_line(path_, e.header_line,
                     "element " + quote(e.name) + " is not supported (only 'face' lists)");
      }
      for (const PlyProperty& prop : e.properties) {
        e.min_binary_size += size_of(prop.is_list ? prop.count_type : prop.type);
        e.min_tokens += 1;
      }
    }
    if (header_.vertex_element < 0) {
      fail_at_line(path_, 1, "the PLY header declares no 'vertex' element");
    }
  }

  void find_xyz(PlyElement& e) const {
    for (int axis = 0; axis < 3; ++axis) {
      const std::string axis_name(1, static_cast<char>('x' + axis));
      for (std::size_t p = 0; p < e.properties.size(); ++p) {
        if (e.properties[p].name == axis_name) e.xyz[axis] = static_cast<int>(p);
      }
      if (e.xyz[axis] < 0) {
        fail_at_line(path_, e.header_line, "element 'vertex' has no property '" + axis_name + "'");
      }
      if (e.properties[static_cast<std::size_t>(e.xyz[axis])].is_list) {
        fail_at_line(path_, e.header_line,
                     "vertex property '" + axis_name + "' must be a scalar, not a list");
      }
    }
  }

  void find_index_list(PlyElement& e) const {
    for (std::size_t p = 0; p < e.properties.size() && e.xyz[0] < 0; ++p) {
      if (e.properties[p].name == "vertex_indices" || e.properties[p].name == "vertex_index") {
        e.xyz[0] = static_cast<int>(p);
      }
    }
    if (e.xyz[0] < 0) {
      fail_at_line(path_, e.header_line,
                   "element 'face' has no list property 'vertex_indices' or 'vertex_index'");
    }
    const PlyProperty& list = e.properties[static_cast<std::size_t>(e.xyz[0])];
    if (!list.is_list) {
      fail_at_line(path_, e.header_line, "face property " + quote(list.name) + " must be a list");
    }
    if (!is_integer(list.type)) {
      fail_at_line(path_, e.header_line,
                   "the items of face property " + quote(list.name) + " must be integers");
    }
  }

  const std::filesystem::path& path_;
  std::string_view bytes_;
  detail::LineReader lines_;
  PlyHeader header_;
  bool have_format_ = false;
};

}  // namespace

PlyHeader parse_ply_header(const std::filesystem::path& path, std::string_view bytes) {
  return HeaderParser(path, bytes).parse();
}

}  // namespace crumple::io::detail
