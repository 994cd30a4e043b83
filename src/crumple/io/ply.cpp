// Stanford PLY: ascii, binary_little_endian and binary_big_endian.
//
// The file is read into memory in one call and decoded from the buffer. Element counts are
// checked against the file size before anything is allocated: every element has a minimum
// encoded size (its fixed properties and list counts; one token per property in ascii), so a
// header whose counts cannot fit in the bytes that follow it is rejected up front, and every
// allocation stays within a small multiple of the file size.

#include <crumple/core/atomic_file.hpp>
#include <crumple/io/io_detail.hpp>
#include <crumple/io/mesh_io.hpp>

#include <bit>
#include <cstring>
#include <limits>
#include <ostream>

namespace crumple::io {

namespace {

using detail::fail_at_byte;
using detail::fail_at_line;
using detail::quote;

enum class PlyType : std::uint8_t { Int8, UInt8, Int16, UInt16, Int32, UInt32, Float32, Float64 };

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

constexpr std::size_t size_of(PlyType t) {
  switch (t) {
    case PlyType::Int8:
    case PlyType::UInt8: return 1;
    case PlyType::Int16:
    case PlyType::UInt16: return 2;
    case PlyType::Int32:
    case PlyType::UInt32:
    case PlyType::Float32: return 4;
    case PlyType::Float64: return 8;
  }
  return 0;
}

constexpr bool is_integer(PlyType t) { return t != PlyType::Float32 && t != PlyType::Float64; }

struct PlyProperty {
  std::string name;
  PlyType type = PlyType::Float32;  // item type for a list
  bool is_list = false;
  PlyType count_type = PlyType::UInt8;  // lists only
};

enum class Role : std::uint8_t { Skip, Vertex, Face };

struct PlyElement {
  std::string name;
  std::uint64_t count = 0;
  std::vector<PlyProperty> properties;
  std::int64_t header_line = 0;
  Role role = Role::Skip;
  // Vertex: property index of x, y, z. Face: property index of the index list (in xyz[0]).
  std::array<int, 3> xyz{-1, -1, -1};
  // Smallest possible encoded size of one element in binary (every list empty). Only used to
  // reject impossible counts before allocating; a short face list gets its own, clearer error.
  std::uint64_t min_binary_size = 0;
  // Smallest number of ascii tokens of one element (every list empty).
  std::uint64_t min_tokens = 0;
};

struct PlyHeader {
  PlyEncoding encoding = PlyEncoding::Ascii;
  std::vector<PlyElement> elements;
  std::size_t body_offset = 0;      // first byte after the end_header line
  std::int64_t body_first_line = 0;  // line number of that byte
  int vertex_element = -1;
};

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
        e.role = Role::Vertex;
        header_.vertex_element = static_cast<int>(i);
        find_xyz(e);
        if (e.count > static_cast<std::uint64_t>(std::numeric_limits<Index>::max())) {
          fail_at_line(path_, e.header_line,
                       "too many vertices: " + std::to_string(e.count) + " (at most 2^31-1)");
        }
      } else if (e.name == "face") {
        e.role = Role::Face;
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

// ---------------------------------------------------------------------------------------------
// Binary body

template <class U>
U load_unsigned(const unsigned char* p, bool swap) {
  U u;
  std::memcpy(&u, p, sizeof u);
  if (swap) {
    if constexpr (sizeof(U) == 2) u = __builtin_bswap16(u);
    if constexpr (sizeof(U) == 4) u = __builtin_bswap32(u);
    if constexpr (sizeof(U) == 8) u = __builtin_bswap64(u);
  }
  return u;
}

double decode_real(const unsigned char* p, PlyType t, bool swap) {
  switch (t) {
    case PlyType::Int8: return static_cast<std::int8_t>(p[0]);
    case PlyType::UInt8: return p[0];
    case PlyType::Int16: return static_cast<std::int16_t>(load_unsigned<std::uint16_t>(p, swap));
    case PlyType::UInt16: return load_unsigned<std::uint16_t>(p, swap);
    case PlyType::Int32: return static_cast<std::int32_t>(load_unsigned<std::uint32_t>(p, swap));
    case PlyType::UInt32: return load_unsigned<std::uint32_t>(p, swap);
    case PlyType::Float32: return std::bit_cast<float>(load_unsigned<std::uint32_t>(p, swap));
    case PlyType::Float64: return std::bit_cast<double>(load_unsigned<std::uint64_t>(p, swap));
  }
  return 0;
}

// Integer types only.
std::int64_t decode_int(const unsigned char* p, PlyType t, bool swap) {
  switch (t) {
    case PlyType::Int8: return static_cast<std::int8_t>(p[0]);
    case PlyType::UInt8: return p[0];
    case PlyType::Int16: return static_cast<std::int16_t>(load_unsigned<std::uint16_t>(p, swap));
    case PlyType::UInt16: return load_unsigned<std::uint16_t>(p, swap);
    case PlyType::Int32: return static_cast<std::int32_t>(load_unsigned<std::uint32_t>(p, swap));
    case PlyType::UInt32: return load_unsigned<std::uint32_t>(p, swap);
    case PlyType::Float32:
    case PlyType::Float64: break;
  }
  return 0;
}

class BinaryBody {
 public:
  BinaryBody(const std::filesystem::path& path, std::string_view bytes, const PlyHeader& header)
      : path_(path),
        data_(reinterpret_cast<const unsigned char*>(bytes.data())),
        size_(bytes.size()),
        pos_(header.body_offset),
        header_(header),
        swap_((header.encoding == PlyEncoding::BinaryBigEndian) !=
              (std::endian::native == std::endian::big)) {}

  MeshData read() {
    check_sizes();
    MeshData mesh;
    for (const PlyElement& e : header_.elements) {
      switch (e.role) {
        case Role::Vertex: read_vertices(e, mesh.positions); break;
        case Role::Face: read_faces(e, mesh.faces); break;
        case Role::Skip: skip_element(e); break;
      }
    }
    if (pos_ != size_) {
      fail_at_byte(path_, static_cast<std::int64_t>(pos_),
                   std::to_string(size_ - pos_) +
                       " unexpected bytes after the last element (do the header counts match the data?)");
    }
    return mesh;
  }

 private:
  // Rejects counts that cannot fit in the body, before any allocation.
  void check_sizes() const {
    const std::uint64_t body = size_ - pos_;
    std::uint64_t needed = 0;
    for (const PlyElement& e : header_.elements) {
      if (e.min_binary_size == 0) continue;
      const std::uint64_t max_count = (body - needed) / e.min_binary_size;
      if (e.count > max_count) {
        fail_at_line(path_, e.header_line,
                     "the header declares " + std::to_string(e.count) + " " + quote(e.name) +
                         " elements of at least " + std::to_string(e.min_binary_size) +
                         (e.min_binary_size == 1 ? " byte" : " bytes") +
                         " each, which cannot fit in the " + std::to_string(body) +
                         " bytes after the header (file truncated or header corrupt)");
      }
      needed += e.count * e.min_binary_size;
    }
  }

  [[noreturn]] void fail_truncated(std::size_t needed, const PlyElement& e, std::uint64_t i,
                                   const std::string& what) const {
    fail_at_byte(path_, static_cast<std::int64_t>(pos_),
                 "unexpected end of file: expected " + std::to_string(needed) + " bytes for " +
                     what + " of " + quote(e.name) + " " + std::to_string(i) + " (of " +
                     std::to_string(e.count) + "), but only " + std::to_string(size_ - pos_) +
                     " remain");
  }

  void require(std::size_t needed, const PlyElement& e, std::uint64_t i,
               const std::string_view property) const {
    if (size_ - pos_ < needed) fail_truncated(needed, e, i, "property " + quote(property));
  }

  // Stride of an element without lists, or 0 when it has a list.
  static std::size_t fixed_stride(const PlyElement& e) {
    std::size_t stride = 0;
    for (const PlyProperty& p : e.properties) {
      if (p.is_list) return 0;
      stride += size_of(p.type);
    }
    return stride;
  }

  // Reads a list count at pos_ and advances; checks that the items fit.
  std::size_t read_list_count(const PlyElement& e, std::uint64_t i, const PlyProperty& p) {
    require(size_of(p.count_type), e, i, p.name);
    const std::int64_t n = decode_int(data_ + pos_, p.count_type, swap_);
    if (n < 0) {
      fail_at_byte(path_, static_cast<std::int64_t>(pos_),
                   "negative list length " + std::to_string(n) + " in property " + quote(p.name) +
                       " of " + quote(e.name) + " " + std::to_string(i));
    }
    pos_ += size_of(p.count_type);
    const std::uint64_t bytes = static_cast<std::uint64_t>(n) * size_of(p.type);
    if (size_ - pos_ < bytes) {
      fail_truncated(static_cast<std::size_t>(bytes), e, i,
                     std::to_string(n) + " items of list " + quote(p.name));
    }
    return static_cast<std::size_t>(n);
  }

  void skip_element(const PlyElement& e) {
    const std::size_t stride = fixed_stride(e);
    if (stride != 0 || e.properties.empty()) {
      const std::uint64_t bytes = e.count * stride;  // fits: checked by check_sizes
      if (size_ - pos_ < bytes) {
        const std::uint64_t i = (size_ - pos_) / stride;
        pos_ += i * stride;
        fail_truncated(stride, e, i, "all properties");
      }
      pos_ += bytes;
      return;
    }
    for (std::uint64_t i = 0; i < e.count; ++i) skip_properties(e, i, -1);
  }

  // Skips the properties of element i after property `from` (all of them for -1).
  void skip_properties(const PlyElement& e, std::uint64_t i, int from) {
    for (std::size_t p = static_cast<std::size_t>(from + 1); p < e.properties.size(); ++p) {
      const PlyProperty& prop = e.properties[p];
      if (prop.is_list) {
        pos_ += read_list_count(e, i, prop) * size_of(prop.type);
      } else {
        require(size_of(prop.type), e, i, prop.name);
        pos_ += size_of(prop.type);
      }
    }
  }

  void read_vertices(const PlyElement& e, Positions& positions) {
    const std::size_t stride = fixed_stride(e);
    positions.resize(e.count);  // checked against the file size by check_sizes
    if (stride != 0) {
      std::array<std::size_t, 3> offset{};
      std::array<PlyType, 3> type{};
      for (int a = 0; a < 3; ++a) {
        const auto p = static_cast<std::size_t>(e.xyz[a]);
        for (std::size_t q = 0; q < p; ++q) offset[a] += size_of(e.properties[q].type);
        type[a] = e.properties[p].type;
      }
      const std::uint64_t available = (size_ - pos_) / stride;
      for (std::uint64_t i = 0; i < e.count; ++i) {
        if (i >= available) fail_truncated(stride, e, i, "all properties");
        const unsigned char* row = data_ + pos_;
        Vec3& x = positions[i];
        for (int a = 0; a < 3; ++a) x[a] = decode_real(row + offset[a], type[a], swap_);
        if (!x.allFinite()) fail_non_finite(i);
        pos_ += stride;
      }
      return;
    }
    // Vertices with a list property (rare): property by property.
    for (std::uint64_t i = 0; i < e.count; ++i) {
      const std::size_t start = pos_;
      for (std::size_t p = 0; p < e.properties.size(); ++p) {
        const PlyProperty& prop = e.properties[p];
        if (prop.is_list) {
          pos_ += read_list_count(e, i, prop) * size_of(prop.type);
          continue;
        }
        require(size_of(prop.type), e, i, prop.name);
        for (int a = 0; a < 3; ++a) {
          if (static_cast<int>(p) == e.xyz[a]) positions[i][a] = decode_real(data_ + pos_, prop.type, swap_);
        }
        pos_ += size_of(prop.type);
      }
      if (!positions[i].allFinite()) {
        pos_ = start;
        fail_non_finite(i);
      }
    }
  }

  [[noreturn]] void fail_non_finite(std::uint64_t i) const {
    fail_at_byte(path_, static_cast<std::int64_t>(pos_),
                 "vertex " + std::to_string(i) + " has a non-finite coordinate");
  }

  void read_faces(const PlyElement& e, std::vector<Face>& faces) {
    const std::int64_t nv =
        static_cast<std::int64_t>(header_.elements[static_cast<std::size_t>(header_.vertex_element)].count);
    const auto list_index = static_cast<std::size_t>(e.xyz[0]);
    const PlyProperty& list = e.properties[list_index];
    const std::size_t item = size_of(list.type);
    // Reserve no more triangles than the remaining bytes can hold, whatever the header says.
    const std::uint64_t fit = (size_ - pos_) / (size_of(list.count_type) + 3 * item);
    faces.reserve(faces.size() + static_cast<std::size_t>(std::min<std::uint64_t>(e.count, fit)));
    for (std::uint64_t i = 0; i < e.count; ++i) {
      skip_properties_before(e, i, list_index);
      const std::size_t count_at = pos_;
      const std::size_t n = read_list_count(e, i, list);
      if (n < 3) {
        fail_at_byte(path_, static_cast<std::int64_t>(count_at),
                     "face " + std::to_string(i) + " has " + std::to_string(n) +
                         " vertices (at least 3 needed)");
      }
      Index first = 0;
      Index previous = 0;
      for (std::size_t k = 0; k < n; ++k) {
        const std::int64_t id = decode_int(data_ + pos_, list.type, swap_);
        if (id < 0 || id >= nv) {
          fail_at_byte(path_, static_cast<std::int64_t>(pos_),
                       "face " + std::to_string(i) + " has vertex index " + std::to_string(id) +
                           " outside [0, " + std::to_string(nv) + ")");
        }
        pos_ += item;
        const auto v = static_cast<Index>(id);
        if (k == 0) {
          first = v;
        } else if (k >= 2) {
          const Face t{first, previous, v};
          if (const auto problem = detail::repeated_vertex(t, 0)) {
            fail_at_byte(path_, static_cast<std::int64_t>(count_at), "face " + std::to_string(i) + ": " + *problem);
          }
          faces.push_back(t);
        }
        previous = v;
      }
      if (faces.size() > static_cast<std::size_t>(std::numeric_limits<Index>::max())) {
        fail_at_byte(path_, static_cast<std::int64_t>(pos_), "too many triangles (at most 2^31-1)");
      }
      skip_properties(e, i, static_cast<int>(list_index));
    }
  }

  void skip_properties_before(const PlyElement& e, std::uint64_t i, std::size_t end) {
    for (std::size_t p = 0; p < end; ++p) {
      const PlyProperty& prop = e.properties[p];
      if (prop.is_list) {
        pos_ += read_list_count(e, i, prop) * size_of(prop.type);
      } else {
        require(size_of(prop.type), e, i, prop.name);
        pos_ += size_of(prop.type);
      }
    }
  }

  const std::filesystem::path& path_;
  const unsigned char* data_;
  std::size_t size_;
  std::size_t pos_;
  const PlyHeader& header_;
  bool swap_;
};

// ---------------------------------------------------------------------------------------------
// Ascii body

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
        case Role::Vertex: read_vertices(e, mesh.positions); break;
        case Role::Face: read_faces(e, mesh.faces); break;
        case Role::Skip:
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

void append_header(std::string& out, std::string_view format, std::size_t nv, std::size_t nf) {
  out += "ply\nformat ";
  out += format;
  out += " 1.0\ncomment written by crumple\nelement vertex ";
  detail::append_int(out, static_cast<std::int64_t>(nv));
  out += "\nproperty double x\nproperty double y\nproperty double z\nelement face ";
  detail::append_int(out, static_cast<std::int64_t>(nf));
  out += "\nproperty list uchar int vertex_indices\nend_header\n";
}

template <class U>
void append_raw(std::string& out, U value, bool swap) {
  if (swap) {
    if constexpr (sizeof(U) == 4) value = __builtin_bswap32(value);
    if constexpr (sizeof(U) == 8) value = __builtin_bswap64(value);
  }
  char bytes[sizeof(U)];
  std::memcpy(bytes, &value, sizeof(U));
  out.append(bytes, sizeof(U));
}

}  // namespace

MeshData read_ply(const std::filesystem::path& path) {
  const std::string bytes = detail::read_whole_file(path);
  const PlyHeader header = HeaderParser(path, bytes).parse();
  if (header.encoding == PlyEncoding::Ascii) return AsciiBody(path, bytes, header).read();
  return BinaryBody(path, bytes, header).read();
}

void write_ply(const std::filesystem::path& path, PositionsView positions,
               std::span<const Face> faces, PlyEncoding encoding) {
  detail::check_mesh_for_writing(positions, faces);
  std::string out;
  if (encoding == PlyEncoding::Ascii) {
    out.reserve(256 + positions.size() * 64 + faces.size() * 24);
    append_header(out, "ascii", positions.size(), faces.size());
    detail::append_position_lines(out, "", positions);
    detail::append_face_lines(out, "3 ", faces, 0);
  } else {
    const bool big = encoding == PlyEncoding::BinaryBigEndian;
    const bool swap = big != (std::endian::native == std::endian::big);
    out.reserve(256 + positions.size() * 24 + faces.size() * 13);
    append_header(out, big ? "binary_big_endian" : "binary_little_endian", positions.size(),
                  faces.size());
    for (const Vec3& p : positions) {
      for (int a = 0; a < 3; ++a) append_raw(out, std::bit_cast<std::uint64_t>(p[a]), swap);
    }
    for (const Face& f : faces) {
      out += static_cast<char>(3);
      for (const Index id : f) append_raw(out, static_cast<std::uint32_t>(id), swap);
    }
  }
  detail::write_string_atomically(path, out, /*binary=*/true);
}

}  // namespace crumple::io
