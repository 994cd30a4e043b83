// Wavefront OBJ reader: statement forms, relative ids, polygons, and the errors it reports.

#include "io_test_util.hpp"

namespace crumple::io::test {
namespace {

MeshData read_obj_text(const TempDir& dir, const std::string& text, const char* name = "m.obj") {
  write_bytes(dir / name, text);
  return read_obj(dir / name);
}

TEST(Obj, ReferenceFormsAndIgnoredStatements) {
  TempDir dir;
  const MeshData m = read_obj_text(dir,
                                   "# a comment\n"
                                   "mtllib m.mtl\n"
                                   "o object\n"
                                   "g group\n"
                                   "v 0 0 0\n"
                                   "v 1 0 0 1.0\n"           // w is ignored
                                   "v 0 1 0 0.5 0.5 0.5\n"   // trailing RGB colour
                                   "v 1 1 0   # comment after a vertex\n"
                                   "vt 0 0\nvt 1 0\nvt 0 1\n"
                                   "vn 0 0 1\n"
                                   "s off\n"
                                   "usemtl red\n"
                                   "f 1 2 3\n"
                                   "f 1/1 2/2 3/3\n"
                                   "f 1//1 2//1 3//1\n"
                                   "f 1/1/1 2/2/1 3/3/1\n"
                                   "l 1 2\n");
  ASSERT_EQ(m.positions.size(), 4u);
  EXPECT_EQ(m.positions[3], Vec3(1, 1, 0));
  ASSERT_EQ(m.faces.size(), 4u);
  for (const Face& f : m.faces) EXPECT_EQ(f, (Face{0, 1, 2}));
}

TEST(Obj, NegativeIdsCountBackFromTheLastVertexSoFar) {
  TempDir dir;
  const MeshData m = read_obj_text(dir,
                                   "v 0 0 0\nv 1 0 0\nv 0 1 0\n"
                                   "f -3 -2 -1\n"
                                   "v 1 1 0\n"
                                   "f -3/-1 -1/-2 -2//-1\n");
  ASSERT_EQ(m.faces.size(), 2u);
  EXPECT_EQ(m.faces[0], (Face{0, 1, 2}));
  EXPECT_EQ(m.faces[1], (Face{1, 3, 2}));
}

TEST(Obj, PolygonsAreFanTriangulatedInOrder) {
  TempDir dir;
  const MeshData m = read_obj_text(dir,
                                   "v 0 0 0\nv 1 0 0\nv 2 1 0\nv 1 2 0\nv 0 1 0\n"
                                   "f 1 2 3 4 5\n"
                                   "f 5 4 3 2\n");
  const std::vector<Face> expected = {{0, 1, 2}, {0, 2, 3}, {0, 3, 4}, {4, 3, 2}, {4, 2, 1}};
  EXPECT_EQ(m.faces, expected);
}

TEST(Obj, CrlfLineContinuationAndForwardReferences) {
  TempDir dir;
  const MeshData m = read_obj_text(dir,
                                   "f 1 2 \\\r\n"
                                   "  3\r\n"
                                   "v 0 0 0\r\n"
                                   "v 1 \\\n 0 0\r\n"
                                   "v 0 1 0\r\n");
  ASSERT_EQ(m.positions.size(), 3u);
  EXPECT_EQ(m.positions[1], Vec3(1, 0, 0));
  ASSERT_EQ(m.faces.size(), 1u);
  EXPECT_EQ(m.faces[0], (Face{0, 1, 2}));
}

TEST(Obj, NumbersInEveryNotation) {
  TempDir dir;
  const MeshData m = read_obj_text(dir, "v +1.5 -.25 3.\nv 1e3 -2E-2 -0\n\tv\t7\t8\t9\n");
  ASSERT_EQ(m.positions.size(), 3u);
  EXPECT_EQ(m.positions[0], Vec3(1.5, -0.25, 3.0));
  EXPECT_EQ(m.positions[1], Vec3(1000, -0.02, 0));
  EXPECT_TRUE(std::signbit(m.positions[1].z()));
  EXPECT_EQ(m.positions[2], Vec3(7, 8, 9));
}

TEST(Obj, Errors) {
  TempDir dir;
  const fs::path file = dir / "bad.obj";
  struct Case {
    std::string text;
    std::int64_t line;
    std::string needle;
  };
  const std::vector<Case> cases = {
      {"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n", 4, "index 0"},
      {"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n", 4, "vertex index 4 is out of range"},
      {"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 99\n", 5, "99"},
      {"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 5\nf 1 2 99\nv 1 1 1\n", 4,
       "vertex index 5 is out of range: the file has 4 vertices"},
      {"v 0 0 0\nv 1 0 0\nf -1 -2 -3\n", 3, "before the first vertex"},
      {"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2\n", 4, "at least 3 vertices"},
      {"v 0 0 0\nv 1 0 0\nv 0 1 0\nf\n", 4, "at least 3 vertices"},
      {"v 0 0\n", 1, "found 2 numbers"},
      {"v 0 0 0 0 0\n", 1, "found 5 numbers"},
      {"v 0 0 0\n\n\nv 1 zero 0\n", 4, "'zero'"},
      {"v 0 0 nan\n", 1, "non-finite"},
      {"v 0 inf 0\n", 1, "non-finite"},
      {"v 0 1e999 0\n", 1, "non-finite"},
      {"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1/ 2 3\n", 4, "malformed face vertex '1/'"},
      {"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1/1/ 2 3\n", 4, "malformed"},
      {"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1/0 2 3\n", 4, "malformed"},
      {"v 0 0 0\nv 1 0 0\nv 0 1 0\nf a b c\n", 4, "malformed face vertex 'a'"},
      {"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1.5 2 3\n", 4, "malformed"},
      {"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 99999999999\n", 4, "out of range"},
      {"hello world\n", 1, "unknown statement 'hello'"},
      {"v 0 0 0\r\nv 1 0 0\r\nbogus\r\n", 3, "unknown statement 'bogus'"},
      {"v 0 0 0\n\x01\x02\xff\n", 2, "\\x01\\x02\\xFF"},
      {"v 0 0 0x1\n", 1, "'0x1'"},
      {"v 0 0 1,5\n", 1, "'1,5'"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.text);
    write_bytes(file, c.text);
    expect_parse_error([&] { read_obj(file); }, file, At::Line(c.line), c.needle);
  }
}

TEST(Obj, MissingFileAndDirectory) {
  TempDir dir;
  const fs::path missing = dir / "missing.obj";
  expect_parse_error([&] { read_obj(missing); }, missing, At::Nowhere(), "No such file");
  expect_parse_error([&] { read_obj(dir.path()); }, dir.path(), At::Nowhere(), "directory");
  expect_parse_error([&] { read_mesh(missing); }, missing, At::Nowhere(), "cannot open");
}

TEST(Obj, TruncationGivesAnErrorOrAPrefix) {
  // OBJ has no counts: a cut at a line end is a valid shorter file. Anything accepted must be a
  // consistent prefix of the full mesh.
  TempDir dir;
  const fs::path file = dir / "cut.obj";
  const TestMesh mesh = awkward_mesh(3);
  write_obj(file, mesh.positions, mesh.faces);
  const std::string full = read_bytes(file);
  std::size_t rejected = 0;
  for (const std::size_t cut : cut_points(full.size(), 5)) {
    write_bytes(file, full.substr(0, cut));
    try {
      const MeshData m = read_obj(file);
      EXPECT_TRUE(consistent(m)) << "cut at " << cut;
      ASSERT_LE(m.positions.size(), mesh.positions.size());
      ASSERT_LE(m.faces.size(), mesh.faces.size());
      for (std::size_t f = 0; f + 1 < m.faces.size(); ++f) EXPECT_EQ(m.faces[f], mesh.faces[f]);
    } catch (const ParseError& e) {
      ++rejected;
      EXPECT_EQ(e.file(), file.string());
      EXPECT_TRUE(e.line().has_value()) << e.what();
    }
  }
  EXPECT_GT(rejected, 0u);
}

TEST(Obj, EmptyFileIsAnEmptyMesh) {
  TempDir dir;
  const MeshData m = read_obj_text(dir, "");
  EXPECT_TRUE(m.positions.empty());
  EXPECT_TRUE(m.faces.empty());
}

}  // namespace
}  // namespace crumple::io::test
