// Regression (issue 45, defect 8): an empty OBJ was accepted where empty PLY/OFF/X3D were
// rejected, and a face repeating a vertex in an OBJ was reported with 0-based ids and no line
// ("face 0 (0 0 1)" for `f 1 1 2` on line 4). Every format now rejects a mesh without faces
// the same way, and names the offending face at its line (or byte) in the file's numbering.
#include "io_test_util.hpp"

#include <crumple/io/mesh_io.hpp>

#include <string>

namespace crumple::io::test {
namespace {

/// The ParseError `read_mesh(file)` must throw.
ParseError read_mesh_error(const fs::path& file) {
  try {
    read_mesh(file);
  } catch (const ParseError& e) {
    return e;
  }
  ADD_FAILURE() << "no error reading " << file;
  return ParseError(file.string(), {}, "(none)");
}

TEST(MeshValidation, EveryFormatRejectsAMeshWithoutFaces) {
  TempDir dir;
  for (const char* name : {"e.obj", "e.ply", "e.off", "e.x3d"}) {
    SCOPED_TRACE(name);
    write_mesh(dir.path() / name, {}, {});  // a valid file of its format, holding nothing
    const ParseError e = read_mesh_error(dir.path() / name);
    EXPECT_NE(e.message().find("no faces"), std::string::npos) << e.what();
    EXPECT_EQ(e.file(), (dir.path() / name).string());
    // Vertices only: the same.
    write_mesh(dir.path() / name, Positions{Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0)}, {});
    EXPECT_NE(read_mesh_error(dir.path() / name).message().find("3 vertices and no face"), std::string::npos);
  }
  // Zero bytes, or only a comment: rejected by every reader.
  for (const char* name : {"z.obj", "z.ply", "z.off", "z.x3d"}) {
    SCOPED_TRACE(name);
    write_bytes(dir.path() / name, "");
    EXPECT_THROW(read_mesh(dir.path() / name), ParseError);
  }
  write_bytes(dir.path() / "c.obj", "# nothing here\n");
  EXPECT_NE(read_mesh_error(dir.path() / "c.obj").message().find("no faces"), std::string::npos);
}

struct RepeatedCase {
  const char* name;
  std::string text;
  std::int64_t line;
  const char* expected;  // in the message, ids as the file numbers them
};

TEST(MeshValidation, AFaceRepeatingAVertexIsNamedAtItsLineInTheFilesNumbering) {
  TempDir dir;
  const std::vector<RepeatedCase> cases = {
      {"a.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 1 2\n", 4, "triangle 1 1 2 repeats vertex 1"},
      {"b.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n# quad\nf 1 2 3 3\n", 6, "triangle 1 3 3 repeats vertex 3"},
      {"c.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf -1 -2 -1\n", 4, "triangle 3 2 3 repeats vertex 3"},
      {"a.off", "OFF\n3 2 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n3 0 0 1\n", 7, "face 1: triangle 0 0 1 repeats vertex 0"},
      {"a.ply",
       "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
       "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 2 1 2\n",
       13, "face 0: triangle 2 1 2 repeats vertex 2"},
      {"a.x3d",
       "<X3D>\n<Scene>\n<Shape>\n<IndexedFaceSet coordIndex='0 1 2 -1 1 1 2 -1'>\n"
       "<Coordinate point='0 0 0 1 0 0 0 1 0'/>\n</IndexedFaceSet>\n</Shape>\n</Scene>\n</X3D>\n",
       4, "polygon 1: triangle 1 1 2 repeats vertex 1"},
      {"b.x3d",
       "<X3D>\n<Scene>\n<Shape>\n<IndexedTriangleSet index='0 1 2 2 0 2'>\n"
       "<Coordinate point='0 0 0 1 0 0 0 1 0'/>\n</IndexedTriangleSet>\n</Shape>\n</Scene>\n</X3D>\n",
       4, "triangle 1: triangle 2 0 2 repeats vertex 2"},
  };
  for (const RepeatedCase& c : cases) {
    SCOPED_TRACE(c.name);
    write_bytes(dir.path() / c.name, c.text);
    const ParseError e = read_mesh_error(dir.path() / c.name);
    EXPECT_EQ(e.line(), c.line) << e.what();
    EXPECT_NE(e.message().find(c.expected), std::string::npos) << e.what();
  }
}

TEST(MeshValidation, BinaryPlyNamesTheFacesByteOffset) {
  TempDir dir;
  std::string bytes =
      "ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
      "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n";
  const std::size_t body = bytes.size();
  bytes.append(36, '\0');  // three float vertices at the origin
  const std::size_t face_at = bytes.size();
  bytes += '\3';
  for (const std::int32_t id : {0, 2, 2}) bytes.append(reinterpret_cast<const char*>(&id), 4);
  write_bytes(dir.path() / "b.ply", bytes);
  const ParseError e = read_mesh_error(dir.path() / "b.ply");
  EXPECT_EQ(e.byte_offset(), static_cast<std::int64_t>(face_at)) << e.what() << " body at " << body;
  EXPECT_NE(e.message().find("triangle 0 2 2 repeats vertex 2"), std::string::npos) << e.what();
}

}  // namespace
}  // namespace crumple::io::test
