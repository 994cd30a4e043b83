// X3D reader: IndexedFaceSet, IndexedTriangleSet, DEF/USE, and the errors it reports.

#include "io_test_util.hpp"

namespace crumple::io::test {
namespace {

std::string wrap(const std::string& shape_content) {
  return "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n"  // line 1
         "<X3D profile=\"Interchange\" version=\"3.3\">\n"  // line 2
         "<Scene>\n"                                      // line 3
         "<Shape>\n" +                                    // line 4
         shape_content +                                  // from line 5
         "</Shape>\n</Scene>\n</X3D>\n";
}

MeshData read_x3d_text(const TempDir& dir, const std::string& text) {
  write_bytes(dir / "m.x3d", text);
  return read_x3d(dir / "m.x3d");
}

const Positions square = {Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(1, 1, 0), Vec3(0, 1, 0.5)};

TEST(X3d, IndexedFaceSetPolygonsWithAndWithoutCommas) {
  TempDir dir;
  for (const std::string point : {"0 0 0, 1 0 0, 1 1 0, 0 1 0.5", "0 0 0 1 0 0 1 1 0 0 1 0.5",
                                  " 0,0,0 ,1 0 0,\n 1 1 0,\t0 1 5e-1 "}) {
    for (const std::string index : {"0 1 2 3 -1 3 2 1 -1", "0 1 2 3 -1 3 2 1", "0,1,2,3,-1,3,2,1,-1"}) {
      SCOPED_TRACE(point + " | " + index);
      const MeshData m = read_x3d_text(
          dir, wrap("<IndexedFaceSet coordIndex='" + index + "'>\n<Coordinate point='" + point +
                    "'/>\n</IndexedFaceSet>\n"));
      EXPECT_EQ(m.positions, square);
      EXPECT_EQ(m.faces, (std::vector<Face>{{0, 1, 2}, {0, 2, 3}, {3, 2, 1}}));
    }
  }
}

TEST(X3d, IndexedTriangleSetAndCoordinateDouble) {
  TempDir dir;
  const MeshData m = read_x3d_text(
      dir, wrap("<IndexedTriangleSet index='0 1 2, 0 2 3'>\n<CoordinateDouble point='0 0 0, 1 0 0, "
                "1 1 0, 0 1 0.5'/>\n</IndexedTriangleSet>\n"));
  EXPECT_EQ(m.positions, square);
  EXPECT_EQ(m.faces, (std::vector<Face>{{0, 1, 2}, {0, 2, 3}}));
}

TEST(X3d, FirstMeshNodeWinsAndUseFollowsDef) {
  TempDir dir;
  const MeshData m = read_x3d_text(
      dir, "<X3D><Scene>\n"
           "<Transform><Shape><Appearance/>\n"
           "<IndexedFaceSet coordIndex='2 1 0'><Coordinate DEF='pts' point='0 0 0 1 0 0 1 1 0 0 1 0.5'/></IndexedFaceSet>\n"
           "</Shape></Transform>\n"
           "<Shape><IndexedTriangleSet index='1 2 3'><Coordinate USE='pts'/></IndexedTriangleSet></Shape>\n"
           "</Scene></X3D>\n");
  EXPECT_EQ(m.faces, (std::vector<Face>{{2, 1, 0}}));
  // The second shape alone, through USE.
  const MeshData used = read_x3d_text(
      dir, "<X3D><Scene>\n"
           "<Coordinate DEF='pts' point='0 0 0 1 0 0 1 1 0 0 1 0.5'/>\n"
           "<Shape><IndexedTriangleSet index='1 2 3'><Coordinate USE='pts'/></IndexedTriangleSet></Shape>\n"
           "</Scene></X3D>\n");
  EXPECT_EQ(used.positions, square);
  EXPECT_EQ(used.faces, (std::vector<Face>{{1, 2, 3}}));
}

TEST(X3d, CrlfAndEntities) {
  TempDir dir;
  std::string text = wrap("<IndexedFaceSet coordIndex='0&#32;1 2'>\n<Coordinate point='0 0 0\n1 0 0\n0 1 0'/>\n</IndexedFaceSet>\n");
  std::string crlf;
  for (char c : text) crlf += c == '\n' ? std::string("\r\n") : std::string(1, c);
  const MeshData m = read_x3d_text(dir, crlf);
  EXPECT_EQ(m.positions.size(), 3u);
  EXPECT_EQ(m.faces, (std::vector<Face>{{0, 1, 2}}));
}

TEST(X3d, ByteOrderMarkDoctypeAndComments) {
  TempDir dir;
  const std::string text =
      "\xEF\xBB\xBF<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n"
      "<!DOCTYPE X3D PUBLIC \"ISO//Web3D//DTD X3D 3.3//EN\" \"http://www.web3d.org/specifications/x3d-3.3.dtd\">\n"
      "<X3D profile='Interchange' version='3.3'>\n"
      "<!-- <IndexedFaceSet coordIndex='9 9 9'/> in a comment is not a node -->\n"
      "<Scene><Shape>\n"
      "<IndexedFaceSet coordIndex='0 1 9'>\n"  // line 6
      "<Coordinate point='0 0 0 1 0 0 0 1 0'/>\n"
      "</IndexedFaceSet></Shape></Scene></X3D>\n";
  const fs::path file = dir / "bom.x3d";
  write_bytes(file, text);
  expect_parse_error([&] { read_x3d(file); }, file, At::Line(6), "is 9");
  std::string fixed = text;
  fixed.replace(fixed.find("0 1 9"), 5, "0 1 2");
  write_bytes(file, fixed);
  EXPECT_EQ(read_x3d(file).faces, (std::vector<Face>{{0, 1, 2}}));
}

TEST(X3d, Errors) {
  TempDir dir;
  const fs::path file = dir / "bad.x3d";
  const std::string coordinate = "<Coordinate point='0 0 0, 1 0 0, 1 1 0, 0 1 0'/>";
  struct Case {
    std::string text;
    std::optional<std::int64_t> line;
    std::string needle;
  };
  const std::vector<Case> cases = {
      {"", 1, "malformed XML"},
      {"<X3D><Scene>\n<Shape>\n</Scene></X3D>", 3, "malformed XML"},
      {"<html><body/></html>", 1, "not an X3D file: the root element is <html>"},
      {wrap(""), 2, "no <IndexedFaceSet>, <IndexedTriangleSet> or <MassSpring> node"},
      {wrap("<IndexedFaceSet coordIndex='0 1 2'/>\n"), 5, "has no <Coordinate"},
      {wrap("<IndexedFaceSet coordIndex='0 1 2'>\n<Coordinate/>\n</IndexedFaceSet>\n"), 6,
       "<Coordinate> has no 'point' attribute"},
      {wrap("<IndexedFaceSet coordIndex='0 1 2'>\n<Coordinate point='0 0 0 1'/>\n</IndexedFaceSet>\n"), 6,
       "<Coordinate point>: has 4 numbers, expected x y z triples"},
      {wrap("<IndexedFaceSet coordIndex='0 1 2'>\n<Coordinate point='0 0 0 1 0 x 0 1 0'/>\n</IndexedFaceSet>\n"), 6,
       "<Coordinate point>: value 5 is 'x', expected a number"},
      {wrap("<IndexedFaceSet coordIndex='0 1 2'>\n<Coordinate point='0 0 0 1 0 NaN 0 1 0'/>\n</IndexedFaceSet>\n"), 6,
       "value 5 ('NaN') is not finite"},
      {wrap("<IndexedFaceSet coordIndex='0 1 2'>\n<Coordinate point='0 0 0 1 0 1e999 0 1 0'/>\n</IndexedFaceSet>\n"), 6,
       "is not finite"},
      {wrap("\n\n<IndexedFaceSet\n coordIndex='0 1 4 -1'>" + coordinate + "</IndexedFaceSet>\n"), 7,
       "<IndexedFaceSet coordIndex>: value 2 (polygon 0) is 4, expected a vertex id in [0, 4) or -1"},
      {wrap("<IndexedFaceSet coordIndex='0 1 2 -2'>" + coordinate + "</IndexedFaceSet>\n"), 5, "is -2"},
      {wrap("<IndexedFaceSet coordIndex='0 1 2 -1 0 1 -1'>" + coordinate + "</IndexedFaceSet>\n"), 5,
       "polygon 1 has 2 vertices"},
      {wrap("<IndexedFaceSet coordIndex='0 1 2 -1 -1'>" + coordinate + "</IndexedFaceSet>\n"), 5,
       "polygon 1 has 0 vertices"},
      {wrap("<IndexedFaceSet coordIndex='0 1 2.5'>" + coordinate + "</IndexedFaceSet>\n"), 5,
       "value 2 is '2.5', expected an integer"},
      {wrap("<IndexedTriangleSet index='0 1 2 3'>" + coordinate + "</IndexedTriangleSet>\n"), 5,
       "has 4 vertex ids, expected 3 per triangle"},
      {wrap("<IndexedTriangleSet index='0 1 7'>" + coordinate + "</IndexedTriangleSet>\n"), 5,
       "triangle 0 has vertex id 7 outside [0, 4)"},
      {wrap("<IndexedTriangleSet index='0 1 2'><Coordinate USE='nothing'/></IndexedTriangleSet>\n"), 5,
       "refers to no <Coordinate DEF=...>"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.needle);
    write_bytes(file, c.text);
    expect_parse_error([&] { read_x3d(file); }, file, At{c.line, std::nullopt}, c.needle);
  }
}

TEST(X3d, TruncatedFilesAreRejected) {
  TempDir dir;
  const fs::path file = dir / "cut.x3d";
  const TestMesh mesh = awkward_mesh(2);
  write_x3d(file, mesh.positions, mesh.faces);
  const std::string full = read_bytes(file);
  const std::size_t root_closed = full.rfind("</X3D>");
  for (const std::size_t cut : cut_points(full.size(), 5)) {
    write_bytes(file, full.substr(0, cut));
    try {
      const MeshData m = read_x3d(file);
      EXPECT_GE(cut, root_closed + 6) << "cut at " << cut << " was accepted";
      EXPECT_TRUE(consistent(m));
    } catch (const ParseError& e) {
      EXPECT_EQ(e.file(), file.string());
      EXPECT_TRUE(e.line().has_value()) << e.what();
    }
  }
}

}  // namespace
}  // namespace crumple::io::test
