// PLY reader: every scalar type, both byte orders and ascii, skipped elements and lists,
// polygons, and the errors it reports (header lines, body byte offsets, impossible counts).

#include "io_test_util.hpp"

#include <cstring>

namespace crumple::io::test {
namespace {

// ---------------------------------------------------------------------------------------------
// A tiny PLY writer for test files of any layout.

struct Field {
  std::string type;            // scalar type, or item type of a list
  std::vector<double> values;  // one value for a scalar
  std::string count_type;      // non-empty for a list
};

struct Element {
  std::string name;
  std::vector<std::string> properties;  // header lines after "property "
  std::vector<std::vector<Field>> rows;
};

template <class T>
void put(std::string& out, T value, bool big) {
  char bytes[sizeof(T)];
  std::memcpy(bytes, &value, sizeof(T));
  if (big == (std::endian::native == std::endian::little)) std::reverse(bytes, bytes + sizeof(T));
  out.append(bytes, sizeof(T));
}

void put_value(std::string& out, const std::string& type, double v, bool big) {
  if (type == "char" || type == "int8") return put(out, static_cast<std::int8_t>(v), big);
  if (type == "uchar" || type == "uint8") return put(out, static_cast<std::uint8_t>(v), big);
  if (type == "short" || type == "int16") return put(out, static_cast<std::int16_t>(v), big);
  if (type == "ushort" || type == "uint16") return put(out, static_cast<std::uint16_t>(v), big);
  if (type == "int" || type == "int32") return put(out, static_cast<std::int32_t>(v), big);
  if (type == "uint" || type == "uint32") return put(out, static_cast<std::uint32_t>(v), big);
  if (type == "float" || type == "float32") return put(out, static_cast<float>(v), big);
  if (type == "double" || type == "float64") return put(out, v, big);
  ADD_FAILURE() << "bad type " << type;
}

std::string ascii_value(double v) {
  char buffer[64];
  std::snprintf(buffer, sizeof buffer, "%.17g", v);
  return buffer;
}

std::string make_ply(const std::vector<Element>& elements, PlyEncoding encoding,
                     const std::string& eol = "\n") {
  const char* format = encoding == PlyEncoding::Ascii                ? "ascii"
                       : encoding == PlyEncoding::BinaryLittleEndian ? "binary_little_endian"
                                                                     : "binary_big_endian";
  std::string out = "ply" + eol + "format " + format + " 1.0" + eol + "comment test file" + eol;
  for (const Element& e : elements) {
    out += "element " + e.name + " " + std::to_string(e.rows.size()) + eol;
    for (const std::string& p : e.properties) out += "property " + p + eol;
  }
  out += "end_header" + eol;
  const bool big = encoding == PlyEncoding::BinaryBigEndian;
  for (const Element& e : elements) {
    for (const auto& row : e.rows) {
      std::string line;
      for (const Field& f : row) {
        if (encoding == PlyEncoding::Ascii) {
          if (!f.count_type.empty()) line += std::to_string(f.values.size()) + " ";
          for (double v : f.values) line += ascii_value(v) + " ";
        } else {
          if (!f.count_type.empty()) put_value(out, f.count_type, static_cast<double>(f.values.size()), big);
          for (double v : f.values) put_value(out, f.type, v, big);
        }
      }
      if (encoding == PlyEncoding::Ascii) out += line + eol;
    }
  }
  return out;
}

Field scalar(const std::string& type, double v) { return {type, {v}, ""}; }
Field list(const std::string& count_type, const std::string& type, std::vector<double> v) {
  return {type, std::move(v), count_type};
}

// Vertices with x, y, z of three different types scattered among colour, a list and more;
// faces with an int before the index list, a float list after it; elements before and after.
std::vector<Element> mixed_layout() {
  Element material{"material", {"char a", "list int uchar name"}, {}};
  material.rows = {{scalar("char", -5), list("int", "uchar", {104, 105})},
                   {scalar("char", 7), list("int", "uchar", {})}};
  Element vertex{"vertex",
                 {"uchar red", "float x", "list uchar int extra", "int16 y", "float64 z",
                  "ushort w"},
                 {}};
  const double xs[] = {0.5, -1.25, 3.0, 0.0, 2.75};
  const double ys[] = {-3, 7, 0, 32767, -32768};
  const double zs[] = {1.0 / 3.0, -0.1, 1e-300, 2.5, -7.0};
  for (int i = 0; i < 5; ++i) {
    vertex.rows.push_back({scalar("uchar", 200 + i), scalar("float", xs[i]),
                           list("uchar", "int", std::vector<double>(static_cast<std::size_t>(i), -1.0)),
                           scalar("int16", ys[i]), scalar("float64", zs[i]), scalar("ushort", 65535)});
  }
  Element face{"face",
               {"int flags", "list uint16 uint32 vertex_index", "list uchar float texcoord"},
               {}};
  face.rows = {{scalar("int", -1), list("uint16", "uint32", {0, 1, 2, 3}), list("uchar", "float", {0.5, 0.25})},
               {scalar("int", 2), list("uint16", "uint32", {4, 3, 2}), list("uchar", "float", {})},
               {scalar("int", 3), list("uint16", "uint32", {0, 2, 4, 1, 3}), list("uchar", "float", {1})}};
  Element edge{"edge", {"int vertex1", "int vertex2"}, {{scalar("int", 0), scalar("int", 1)}}};
  return {material, vertex, face, edge};
}

const Positions mixed_positions = {Vec3(0.5, -3, 1.0 / 3.0), Vec3(-1.25, 7, -0.1), Vec3(3.0, 0, 1e-300),
                                   Vec3(0.0, 32767, 2.5), Vec3(2.75, -32768, -7.0)};
const std::vector<Face> mixed_faces = {{0, 1, 2}, {0, 2, 3}, {4, 3, 2},
                                       {0, 2, 4}, {0, 4, 1}, {0, 1, 3}};

constexpr PlyEncoding all_encodings[] = {PlyEncoding::Ascii, PlyEncoding::BinaryLittleEndian,
                                         PlyEncoding::BinaryBigEndian};

std::string encoding_name(PlyEncoding e) {
  return e == PlyEncoding::Ascii ? "ascii" : e == PlyEncoding::BinaryLittleEndian ? "le" : "be";
}

TEST(Ply, MixedLayoutInEveryEncoding) {
  TempDir dir;
  for (const PlyEncoding encoding : all_encodings) {
    for (const std::string eol : {"\n", "\r\n"}) {
      SCOPED_TRACE(encoding_name(encoding) + (eol == "\n" ? " LF" : " CRLF"));
      const fs::path file = dir / "mixed.ply";
      write_bytes(file, make_ply(mixed_layout(), encoding, eol));
      const MeshData m = read_ply(file);
      EXPECT_TRUE(same_bits(m.positions, mixed_positions));
      EXPECT_EQ(m.faces, mixed_faces);
    }
  }
}

TEST(Ply, EveryScalarTypeForCoordinatesAndIndices) {
  TempDir dir;
  const char* types[] = {"char", "uchar", "short", "ushort", "int", "uint", "float", "double",
                         "int8", "uint8", "int16", "uint16", "int32", "uint32", "float32", "float64"};
  const char* index_types[] = {"char", "uchar", "short", "ushort", "int", "uint",
                               "int8", "uint8", "int16", "uint16", "int32", "uint32"};
  for (const PlyEncoding encoding : all_encodings) {
    for (const char* type : types) {
      for (const char* index_type : index_types) {
        SCOPED_TRACE(encoding_name(encoding) + " " + type + " " + index_type);
        Element vertex{"vertex", {std::string(type) + " x", std::string(type) + " y", std::string(type) + " z"}, {}};
        for (int i = 0; i < 4; ++i) {
          vertex.rows.push_back({scalar(type, i), scalar(type, 2 * i), scalar(type, 100 + i)});
        }
        Element face{"face", {std::string("list ") + index_type + " " + index_type + " vertex_indices"}, {}};
        face.rows = {{list(index_type, index_type, {3, 2, 1, 0})}};
        const fs::path file = dir / "t.ply";
        write_bytes(file, make_ply({vertex, face}, encoding));
        const MeshData m = read_ply(file);
        ASSERT_EQ(m.positions.size(), 4u);
        EXPECT_EQ(m.positions[3], Vec3(3, 6, 103));
        EXPECT_EQ(m.faces, (std::vector<Face>{{3, 2, 1}, {3, 1, 0}}));
      }
    }
  }
}

TEST(Ply, NoFaceElementGivesPointsOnly) {
  TempDir dir;
  Element vertex{"vertex", {"float x", "float y", "float z"}, {{scalar("float", 1), scalar("float", 2), scalar("float", 3)}}};
  const fs::path file = dir / "points.ply";
  write_bytes(file, make_ply({vertex}, PlyEncoding::BinaryLittleEndian));
  const MeshData m = read_ply(file);
  EXPECT_EQ(m.positions, (Positions{Vec3(1, 2, 3)}));
  EXPECT_TRUE(m.faces.empty());
}

TEST(Ply, EmptyElementsWithHugeCountsAreSkippedInstantly) {
  TempDir dir;
  const fs::path file = dir / "empty-elements.ply";
  for (const char* format : {"ascii", "binary_little_endian"}) {
    SCOPED_TRACE(format);
    write_bytes(file, std::string("ply\nformat ") + format +
                          " 1.0\nelement nothing 1000000000000000000\nelement vertex 0\n"
                          "property float x\nproperty float y\nproperty float z\nend_header\n");
    const MeshData m = read_ply(file);
    EXPECT_TRUE(m.positions.empty());
  }
}

// A simple binary file: 3 float vertices, 1 triangle, with byte offsets known.
struct SimpleBinary {
  std::string header;
  std::string bytes;
};

SimpleBinary simple_binary(std::array<double, 9> coordinates = {0, 0, 0, 1, 0, 0, 0, 1, 0},
                           std::vector<double> face = {0, 1, 2}) {
  Element vertex{"vertex", {"float x", "float y", "float z"}, {}};
  for (int i = 0; i < 3; ++i) {
    vertex.rows.push_back({scalar("float", coordinates[3 * i]), scalar("float", coordinates[3 * i + 1]),
                           scalar("float", coordinates[3 * i + 2])});
  }
  Element faces{"face", {"list uchar int vertex_indices"}, {{list("uchar", "int", face)}}};
  SimpleBinary s;
  s.bytes = make_ply({vertex, faces}, PlyEncoding::BinaryLittleEndian);
  s.header = s.bytes.substr(0, s.bytes.find("end_header\n") + 11);
  return s;
}

TEST(Ply, BinaryBodyErrorsNameTheByteOffset) {
  TempDir dir;
  const fs::path file = dir / "bad.ply";
  const auto h = static_cast<std::int64_t>(simple_binary().header.size());
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  struct Case {
    std::string bytes;
    std::int64_t offset;
    std::string needle;
  };
  const std::vector<Case> cases = {
      {simple_binary({0, 0, 0, 1, 0, 0, 0, 1, 0}, {0, 1, 3}).bytes, h + 36 + 1 + 8, "vertex index 3 outside [0, 3)"},
      {simple_binary({0, 0, 0, 1, 0, 0, 0, 1, 0}, {0, -1, 2}).bytes, h + 36 + 1 + 4, "vertex index -1"},
      {simple_binary({0, 0, 0, 1, 0, 0, 0, 1, 0}, {0, 1}).bytes + std::string(4, '\0'), h + 36, "face 0 has 2 vertices"},
      {simple_binary({0, 0, 0, 1, nan, 0, 0, 1, 0}).bytes, h + 12, "vertex 1 has a non-finite coordinate"},
      {simple_binary({0, 0, 0, 1, 0, 0, 0, 1, -inf}).bytes, h + 24, "vertex 2 has a non-finite coordinate"},
      {simple_binary().bytes + "extra", h + 49, "5 unexpected bytes after the last element"},
      // A quad cut short: the body is long enough for a triangle, so the up-front size check
      // passes and the reader meets the end of the file inside the index list.
      {simple_binary({0, 0, 0, 1, 0, 0, 0, 1, 0}, {0, 1, 2, 1}).bytes.substr(0, static_cast<std::size_t>(h + 51)),
       h + 37,
       "unexpected end of file: expected 16 bytes for 4 items of list 'vertex_indices' of 'face' 0 (of 1), "
       "but only 14 remain"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.needle);
    write_bytes(file, c.bytes);
    expect_parse_error([&] { read_ply(file); }, file, At::Byte(c.offset), c.needle);
  }
}

TEST(Ply, HeaderErrorsNameTheLine) {
  TempDir dir;
  const fs::path file = dir / "bad.ply";
  const std::string vertex = "element vertex 1\nproperty float x\nproperty float y\nproperty float z\n";
  const std::string body = std::string(12, '\0');
  struct Case {
    std::string bytes;
    std::int64_t line;
    std::string needle;
  };
  const std::vector<Case> cases = {
      {"", 1, "not a PLY file"},
      {"plyx\n", 1, "not a PLY file"},
      {"PLY\nformat ascii 1.0\n", 1, "not a PLY file"},
      {"\x89PNG\r\n\x1a\n", 1, "not a PLY file"},
      {"ply\nformat binary 1.0\nend_header\n", 2, "expected 'format ascii|binary_little_endian|binary_big_endian 1.0'"},
      {"ply\nformat ascii 2.0\nend_header\n", 2, "unsupported PLY version '2.0'"},
      {"ply\nformat ascii 1.0\nformat ascii 1.0\n", 3, "a second 'format'"},
      {"ply\nelement vertex 1\n", 2, "'element' before the 'format' line"},
      {"ply\nformat ascii 1.0\nproperty float x\n", 3, "'property' before any 'element'"},
      {"ply\nformat ascii 1.0\nelement vertex 1\nproperty flt x\n", 4, "unknown type 'flt'"},
      {"ply\nformat ascii 1.0\nelement vertex 1\nproperty list float int x\n", 4, "count type"},
      {"ply\nformat ascii 1.0\nelement vertex 1\nproperty float\n", 4, "expected 'property <type> <name>'"},
      {"ply\nformat ascii 1.0\nelement vertex -1\n", 3, "non-negative integer, found '-1'"},
      {"ply\nformat ascii 1.0\nelement vertex 18446744073709551616\n", 3, "non-negative integer"},
      {"ply\nformat ascii 1.0\nelement vertex many\n", 3, "found 'many'"},
      {"ply\nformat ascii 1.0\nelement vertex 1\nelement vertex 1\n", 4, "a second element named 'vertex'"},
      {"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float x\n", 5, "a second property named 'x'"},
      {"ply\nformat ascii 1.0\nwhatever\nend_header\n", 3, "unexpected 'whatever' in the PLY header"},
      {"ply\nformat ascii 1.0\n" + vertex, 6, "no 'end_header'"},
      {"ply\nformat ascii 1.0\n" + vertex + "end_header extra\n", 7, "unexpected text after 'end_header'"},
      {"ply\nformat ascii 1.0\nelement vertex 1\nproperty \x01\x02 x\nend_header\n", 4, "binary data in the PLY header"},
      {"ply\nend_header\n", 2, "no 'format' line"},
      {"ply\nformat ascii 1.0\nend_header\n", 1, "no 'vertex' element"},
      {"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nend_header\n", 3,
       "element 'vertex' has no property 'z'"},
      {"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty list uchar float z\nend_header\n",
       3, "'z' must be a scalar"},
      {"ply\nformat binary_little_endian 1.0\n" + vertex + "element face 0\nproperty int flags\nend_header\n" + body, 7,
       "no list property 'vertex_indices'"},
      {"ply\nformat binary_little_endian 1.0\n" + vertex + "element face 0\nproperty int vertex_indices\nend_header\n" + body, 7,
       "must be a list"},
      {"ply\nformat binary_little_endian 1.0\n" + vertex + "element face 0\nproperty list uchar float vertex_indices\nend_header\n" + body,
       7, "must be integers"},
      {"ply\nformat binary_little_endian 1.0\n" + vertex + "element tristrips 0\nproperty list int int vertex_indices\nend_header\n" + body,
       7, "'tristrips' is not supported"},
      // Counts that cannot fit: rejected before allocation, naming the element's header line.
      {"ply\nformat binary_little_endian 1.0\nelement vertex 2000000000\nproperty float x\nproperty float y\nproperty float z\nend_header\n" + body,
       3, "the header declares 2000000000 'vertex' elements of at least 12 bytes each, which cannot fit in the 12 bytes"},
      {"ply\nformat binary_big_endian 1.0\nelement vertex 2000000000\nproperty uchar x\nproperty uchar y\nproperty uchar z\nend_header\n" + body,
       3, "cannot fit"},
      {"ply\nformat binary_little_endian 1.0\nelement vertex 3000000000\nproperty float x\nproperty float y\nproperty float z\nend_header\n" + body,
       3, "too many vertices"},
      {"ply\nformat binary_little_endian 1.0\n" + vertex + "element face 1000000000000\nproperty list uchar int vertex_indices\nend_header\n" + body,
       7, "'face' elements of at least 1 byte each, which cannot fit in the 12 bytes"},
      {"ply\nformat binary_little_endian 1.0\nelement other 9223372036854775807\nproperty double a\n" + vertex + "end_header\n" + body,
       3, "cannot fit"},
      {"ply\nformat ascii 1.0\nelement vertex 1000000000\nproperty float x\nproperty float y\nproperty float z\nend_header\n0 0 0\n",
       3, "cannot fit"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.needle);
    write_bytes(file, c.bytes);
    expect_parse_error([&] { read_ply(file); }, file, At::Line(c.line), c.needle);
  }
}

TEST(Ply, HugeListLengthInABodyIsATruncationNotAnAllocation) {
  TempDir dir;
  const fs::path file = dir / "huge-list.ply";
  std::string bytes =
      "ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
      "property float z\nelement face 1\nproperty list int int vertex_indices\nend_header\n";
  const auto h = static_cast<std::int64_t>(bytes.size());
  bytes += std::string(36, '\0');
  put(bytes, std::int32_t{2147483647}, false);
  bytes += std::string(12, '\0');
  write_bytes(file, bytes);
  expect_parse_error([&] { read_ply(file); }, file, At::Byte(h + 40),
                     "expected 8589934588 bytes for 2147483647 items of list 'vertex_indices'");
}

TEST(Ply, AsciiBodyErrorsNameTheLine) {
  TempDir dir;
  const fs::path file = dir / "bad.ply";
  const std::string header =
      "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
      "element face 1\nproperty list uchar int vertex_indices\nend_header\n";  // 9 lines
  struct Case {
    std::string body;
    std::int64_t line;
    std::string needle;
  };
  const std::vector<Case> cases = {
      {"0 0 0\n1 0 0\n0 1 0\n3 0 1 5\n", 13, "vertex index 5 outside [0, 3)"},
      {"0 0 0\n1 0 0\n0 1 0\n3 0 -1 2\n", 13, "vertex index -1"},
      {"0 0 0\n1 0 0\n0 1 0\n2 0 1\n", 13, "face 0 has 2 vertices"},
      {"0 0 0\n1 zero 0\n0 1 0\n3 0 1 2\n", 11, "expected a number for property 'y' of 'vertex' 1, found 'zero'"},
      {"0 0 0\n1 0 0\n0 1 nan\n3 0 1 2\n", 12, "vertex 2 has a non-finite coordinate 'nan'"},
      {"0 0 0\n1 0 0\n0 1 0\n3 0 1.5 2\n", 13, "expected an integer"},
      {"0 0 0\n1 0 0\n0 1 0\n-3 0 1 2\n", 13, "non-negative list length"},
      {"0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n7\n", 14, "unexpected '7' after the last element"},
      {"0 0 0\n1 0 0\n0 1 0\n3 0 1\n\n\n", 15, "unexpected end of file: expected property 'vertex_indices' of 'face' 0"},
      {"0.0 0.0 0.0\n1 0 0\n0 1\n", 12, "unexpected end of file: expected property"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.needle);
    write_bytes(file, header + c.body);
    expect_parse_error([&] { read_ply(file); }, file, At::Line(c.line), c.needle);
  }
}

TEST(Ply, TruncationIsAlwaysAnError) {
  TempDir dir;
  const fs::path file = dir / "cut.ply";
  for (const PlyEncoding encoding : all_encodings) {
    SCOPED_TRACE(encoding_name(encoding));
    const std::string full = make_ply(mixed_layout(), encoding);
    const std::size_t header_size = full.find("end_header\n") + 11;
    // In ascii, a cut inside the very last number can leave a valid shorter number.
    std::size_t must_fail = full.size();
    if (encoding == PlyEncoding::Ascii) {
      std::size_t end = full.find_last_not_of(" \n");
      must_fail = full.find_last_of(" \n", end) + 1;
    }
    // Every byte of the binary files; every third byte of the ascii one.
    for (const std::size_t cut : cut_points(full.size(), encoding == PlyEncoding::Ascii ? 3 : 1)) {
      write_bytes(file, full.substr(0, cut));
      try {
        const MeshData m = read_ply(file);
        EXPECT_GE(cut, must_fail) << "cut at " << cut << " was accepted";
        EXPECT_TRUE(consistent(m));
      } catch (const ParseError& e) {
        EXPECT_EQ(e.file(), file.string());
        if (cut < header_size || encoding == PlyEncoding::Ascii) {
          EXPECT_TRUE(e.line().has_value()) << "cut at " << cut << ": " << e.what();
        } else if (e.byte_offset()) {
          EXPECT_LE(*e.byte_offset(), static_cast<std::int64_t>(cut)) << e.what();
          EXPECT_GE(*e.byte_offset(), static_cast<std::int64_t>(header_size)) << e.what();
          EXPECT_NE(std::string(e.what()).find("unexpected end of file"), std::string::npos) << e.what();
        } else {
          // Too short for the header's counts: rejected up front at an element's header line.
          EXPECT_TRUE(e.line().has_value()) << e.what();
          EXPECT_NE(std::string(e.what()).find("cannot fit"), std::string::npos) << e.what();
        }
      }
    }
  }
}

TEST(Ply, WriterHeaderIsStandard) {
  TempDir dir;
  const fs::path file = dir / "w.ply";
  write_ply(file, Positions{Vec3(1, 2, 3), Vec3(4, 5, 6), Vec3(7, 8, 9)}, std::vector<Face>{{0, 1, 2}},
            PlyEncoding::BinaryBigEndian);
  const std::string bytes = read_bytes(file);
  const std::string header =
      "ply\nformat binary_big_endian 1.0\ncomment written by crumple\nelement vertex 3\n"
      "property double x\nproperty double y\nproperty double z\nelement face 1\n"
      "property list uchar int vertex_indices\nend_header\n";
  ASSERT_EQ(bytes.substr(0, header.size()), header);
  EXPECT_EQ(bytes.size(), header.size() + 3 * 24 + 13);
  // First coordinate, big-endian 1.0.
  EXPECT_EQ(bytes.substr(header.size(), 8), std::string("\x3f\xf0\0\0\0\0\0\0", 8));
}

}  // namespace
}  // namespace crumple::io::test
