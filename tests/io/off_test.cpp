// OFF reader: header variants, comments, polygons, and the errors it reports.

#include "io_test_util.hpp"

namespace crumple::io::test {
namespace {

MeshData read_off_text(const TempDir& dir, const std::string& text) {
  write_bytes(dir / "m.off", text);
  return read_off(dir / "m.off");
}

TEST(Off, StandardFileWithCommentsAndPolygons) {
  TempDir dir;
  const MeshData m = read_off_text(dir,
                                   "OFF\n"
                                   "# a comment line\n"
                                   "5 2 0\n"
                                   "\n"
                                   "0 0 0\n1 0 0   # trailing comment\n2 1 0\n1 2 0\n0 1 0\n"
                                   "5 0 1 2 3 4\n"
                                   "4 4 3 2 1 255 0 0\n");  // a face colour after the ids
  ASSERT_EQ(m.positions.size(), 5u);
  EXPECT_EQ(m.positions[2], Vec3(2, 1, 0));
  const std::vector<Face> expected = {{0, 1, 2}, {0, 2, 3}, {0, 3, 4}, {4, 3, 2}, {4, 2, 1}};
  EXPECT_EQ(m.faces, expected);
}

TEST(Off, HeaderVariants) {
  TempDir dir;
  const std::vector<std::string> files = {
      "OFF 3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n",              // counts on the header line
      "3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n",                  // no header keyword
      "OFF\r\n3 1\r\n0 0 0\r\n1 0 0\r\n0 1 0\r\n3 0 1 2\r\n",  // CRLF, no edge count
      "COFF\n3 1 0\n0 0 0 255 0 0 255\n1 0 0 0 255 0 255\n0 1 0 0 0 255 255\n3 0 1 2\n",
      "NOFF\n3 1 0\n0 0 0 0 0 1\n1 0 0 0 0 1\n0 1 0 0 0 1\n3 0 1 2\n",
      "STCNOFF\n3 1 0\n0 0 0 0 0 1 1 1 1 1 0 0\n1 0 0 0 0 1 1 1 1 1 0 0\n0 1 0 0 0 1 1 1 1 1 0 0\n3 0 1 2\n",
      "# comment before the header\nOFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2",  // no final newline
  };
  for (const std::string& text : files) {
    SCOPED_TRACE(text);
    const MeshData m = read_off_text(dir, text);
    EXPECT_EQ(m.positions, (Positions{Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0)}));
    EXPECT_EQ(m.faces, (std::vector<Face>{{0, 1, 2}}));
  }
}

TEST(Off, Errors) {
  TempDir dir;
  const fs::path file = dir / "bad.off";
  struct Case {
    std::string text;
    std::int64_t line;
    std::string needle;
  };
  const std::string head = "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n";
  const std::vector<Case> cases = {
      {"", 1, "empty file"},
      {"# only a comment\n", 1, "empty file"},
      {"MESH\n3 1 0\n", 1, "expected an 'OFF' header, found 'MESH'"},
      {"4OFF\n3 1 0\n", 1, "unsupported OFF variant '4OFF'"},
      {"OFF BINARY\n", 1, "found 'BINARY'"},
      {"OFF\n", 1, "unexpected end of file: expected the counts"},
      {"OFF\n3\n", 2, "found 1 numbers"},
      {"OFF\n3 -1 0\n", 2, "found '-1'"},
      {"OFF\n3 1 0 7\n", 2, "found '7'"},
      {"OFF\n1000000000000 1 0\n0 0 0\n", 2, "cannot fit"},
      {"OFF\n3 1000000000 0\n0 0 0\n", 2, "cannot fit"},
      {"OFF\n3 1 0\n0 0 0\n1 0 0\n", 4, "unexpected end of file: expected vertex 2 of 3"},
      {"OFF\n3 1 0\n0 0 0\n1 0\n0 1 0\n3 0 1 2\n", 4, "expected 'x y z' for vertex 1"},
      {"OFF\n3 1 0\n0 0 0\n1 x 0\n0 1 0\n3 0 1 2\n", 4, "found 'x'"},
      {"OFF\n3 1 0\n0 0 0\n1 -nan 0\n0 1 0\n3 0 1 2\n", 4, "vertex 1 has a non-finite coordinate"},
      {head, 5, "unexpected end of file: expected face 0 of 1"},
      {head + "3 0 1 3\n", 6, "face 0 has vertex index 3 outside [0, 3)"},
      {head + "3 0 -1 2\n", 6, "vertex index -1"},
      {head + "2 0 1\n", 6, "face 0 has 2 vertices"},
      {head + "4 0 1 2\n", 6, "declares 4 vertices but lists 3"},
      {head + "three 0 1 2\n", 6, "expected the vertex count of face 0"},
      {head + "3 0 1 2.0\n", 6, "expected a vertex index"},
      {head + "3 0 1 2 red\n", 6, "unexpected 'red' after the 3 vertex indices"},
      {head + "3 0 1 2\n3 0 1 2\n", 7, "unexpected content after the last face"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.text);
    write_bytes(file, c.text);
    expect_parse_error([&] { read_off(file); }, file, At::Line(c.line), c.needle);
  }
}

TEST(Off, TruncationBeforeTheLastNumberIsAnError) {
  TempDir dir;
  const fs::path file = dir / "cut.off";
  const TestMesh mesh = awkward_mesh(3);
  write_off(file, mesh.positions, mesh.faces);
  const std::string full = read_bytes(file);
  const std::size_t last_token = full.find_last_of(" \n", full.size() - 2) + 1;
  for (const std::size_t cut : cut_points(full.size(), 5)) {
    write_bytes(file, full.substr(0, cut));
    try {
      const MeshData m = read_off(file);
      EXPECT_GE(cut, last_token) << "cut at " << cut << " was accepted";
      EXPECT_TRUE(consistent(m));
    } catch (const ParseError& e) {
      EXPECT_EQ(e.file(), file.string());
      EXPECT_TRUE(e.line().has_value()) << e.what();
    }
  }
}

}  // namespace
}  // namespace crumple::io::test
