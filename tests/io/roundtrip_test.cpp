// Write-then-read round trips of every format and encoding, format dispatch, writer checks.

#include "io_test_util.hpp"

#include <crumple/io/mesh_io.hpp>
#include <crumple/io/x3d.hpp>

namespace crumple::io::test {
namespace {

struct FormatCase {
  const char* name;
  const char* extension;
  std::function<void(const fs::path&, PositionsView, std::span<const Face>)> write;
  std::function<MeshData(const fs::path&)> read;
};

std::vector<FormatCase> all_formats() {
  return {
      {"obj", ".obj", write_obj, read_obj},
      {"off", ".off", write_off, read_off},
      {"x3d", ".x3d", write_x3d, read_x3d},
      {"ply_ascii", ".ply",
       [](const fs::path& p, PositionsView v, std::span<const Face> f) {
         write_ply(p, v, f, PlyEncoding::Ascii);
       },
       read_ply},
      {"ply_binary_little_endian", ".ply",
       [](const fs::path& p, PositionsView v, std::span<const Face> f) {
         write_ply(p, v, f, PlyEncoding::BinaryLittleEndian);
       },
       read_ply},
      {"ply_binary_big_endian", ".ply",
       [](const fs::path& p, PositionsView v, std::span<const Face> f) {
         write_ply(p, v, f, PlyEncoding::BinaryBigEndian);
       },
       read_ply},
  };
}

TEST(RoundTrip, EveryFormatIsBitExact) {
  TempDir dir;
  const TestMesh mesh = awkward_mesh(40);
  for (const FormatCase& format : all_formats()) {
    SCOPED_TRACE(format.name);
    const fs::path file = dir / (std::string("mesh_") + format.name + format.extension);
    format.write(file, mesh.positions, mesh.faces);
    const MeshData back = format.read(file);
    EXPECT_TRUE(same_bits(back.positions, mesh.positions));
    EXPECT_EQ(back.faces, mesh.faces);
    // Through the dispatching reader as well.
    const MeshData again = read_mesh_data(file);
    EXPECT_TRUE(same_bits(again.positions, mesh.positions));
    EXPECT_EQ(again.faces, mesh.faces);
  }
}

TEST(RoundTrip, ManySeedsThroughEveryFormat) {
  TempDir dir;
  for (std::uint64_t seed = 1; seed <= 20; ++seed) {
    const TestMesh mesh = awkward_mesh(3, seed);
    for (const FormatCase& format : all_formats()) {
      SCOPED_TRACE(std::string(format.name) + " seed " + std::to_string(seed));
      const fs::path file = dir / (std::string("m") + format.extension);
      format.write(file, mesh.positions, mesh.faces);
      const MeshData back = format.read(file);
      ASSERT_TRUE(same_bits(back.positions, mesh.positions));
      ASSERT_EQ(back.faces, mesh.faces);
    }
  }
}

TEST(RoundTrip, EmptyMesh) {
  TempDir dir;
  for (const FormatCase& format : all_formats()) {
    SCOPED_TRACE(format.name);
    const fs::path file = dir / (std::string("empty") + format.extension);
    format.write(file, {}, {});
    const MeshData back = format.read(file);
    EXPECT_TRUE(back.positions.empty());
    EXPECT_TRUE(back.faces.empty());
  }
}

TEST(RoundTrip, WriteMeshDispatchesByExtension) {
  TempDir dir;
  const TestMesh mesh = awkward_mesh(4);
  for (const char* name : {"a.obj", "b.PLY", "c.Off", "d.x3d"}) {
    SCOPED_TRACE(name);
    write_mesh(dir / name, mesh.positions, mesh.faces);
    const MeshData back = read_mesh_data(dir / name);
    EXPECT_TRUE(same_bits(back.positions, mesh.positions));
    EXPECT_EQ(back.faces, mesh.faces);
  }
  // write_mesh writes binary little-endian PLY.
  EXPECT_NE(read_bytes(dir / "b.PLY").find("format binary_little_endian 1.0\n"), std::string::npos);
}

TEST(RoundTrip, ReadMeshValidates) {
  TempDir dir;
  const TestMesh mesh = awkward_mesh(4);
  write_mesh(dir / "ok.ply", mesh.positions, mesh.faces);
  const TriMesh tri = read_mesh(dir / "ok.ply");
  EXPECT_EQ(tri.num_vertices(), static_cast<Index>(mesh.positions.size()));
  EXPECT_EQ(tri.num_faces(), static_cast<Index>(mesh.faces.size()));

  // A face repeating a vertex: the reader names it at its line, in the file's numbering.
  const fs::path bad = dir / "repeated.obj";
  write_bytes(bad, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 2\n");
  expect_parse_error([&] { read_mesh(bad); }, bad, At::Line(5), "triangle 1 2 2 repeats vertex 2");
}

TEST(Readers, MissingFileIsAParseErrorNamingIt) {
  TempDir dir;
  const std::vector<std::pair<const char*, std::function<void(const fs::path&)>>> readers = {
      {"m.obj", [](const fs::path& p) { read_obj(p); }},
      {"m.ply", [](const fs::path& p) { read_ply(p); }},
      {"m.off", [](const fs::path& p) { read_off(p); }},
      {"m.x3d", [](const fs::path& p) { read_x3d(p); }},
      {"m.x3d", [](const fs::path& p) { read_mass_spring(p); }},
      {"m.ply", [](const fs::path& p) { read_mesh_data(p); }},
      {"m.off", [](const fs::path& p) { read_mesh(p); }},
  };
  for (const auto& [name, read] : readers) {
    SCOPED_TRACE(name);
    const fs::path missing = dir / name;
    expect_parse_error([&] { read(missing); }, missing, At::Nowhere(),
                       "cannot open the file for reading: No such file or directory");
    const fs::path folder = dir / (std::string("folder") + fs::path(name).extension().string());
    fs::create_directories(folder);
    expect_parse_error([&] { read(folder); }, folder, At::Nowhere(), "it is a directory");
  }
}

TEST(Format, FromPath) {
  EXPECT_EQ(format_from_path("a/b/c.obj"), MeshFormat::Obj);
  EXPECT_EQ(format_from_path("C.OBJ"), MeshFormat::Obj);
  EXPECT_EQ(format_from_path("x.ply"), MeshFormat::Ply);
  EXPECT_EQ(format_from_path("x.Off"), MeshFormat::Off);
  EXPECT_EQ(format_from_path("x.X3D"), MeshFormat::X3d);
  EXPECT_EQ(to_string(MeshFormat::X3d), "x3d");
  for (const char* bad : {"x.stl", "noextension", "x.ply.gz", "x."}) {
    SCOPED_TRACE(bad);
    try {
      format_from_path(bad);
      ADD_FAILURE() << "no error";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find(".obj, .ply, .off or .x3d"), std::string::npos) << e.what();
    }
  }
  EXPECT_THROW(read_mesh_data("mesh.stl"), InputError);
}

TEST(Writers, RejectInvalidArguments) {
  TempDir dir;
  TestMesh mesh = awkward_mesh(2);
  const fs::path file = dir / "w.obj";
  for (const FormatCase& format : all_formats()) {
    SCOPED_TRACE(format.name);
    TestMesh nan = mesh;
    nan.positions[3].y() = std::numeric_limits<double>::quiet_NaN();
    EXPECT_THROW(format.write(file, nan.positions, nan.faces), PreconditionError);
    TestMesh out_of_range = mesh;
    out_of_range.faces[1][2] = static_cast<Index>(mesh.positions.size());
    EXPECT_THROW(format.write(file, out_of_range.positions, out_of_range.faces), PreconditionError);
    out_of_range.faces[1][2] = -1;
    EXPECT_THROW(format.write(file, out_of_range.positions, out_of_range.faces), PreconditionError);
    EXPECT_FALSE(fs::exists(file));
  }
  EXPECT_THROW(write_mesh(dir / "x.stl", mesh.positions, mesh.faces), InputError);
}

TEST(Writers, AreAtomicAndLeaveNoTemporaryFiles) {
  TempDir dir;
  const TestMesh mesh = awkward_mesh(3);
  const fs::path file = dir / "m.ply";
  write_ply(file, mesh.positions, mesh.faces, PlyEncoding::Ascii);
  // Overwrite in place; a failed write (bad argument) leaves the previous file untouched.
  write_ply(file, mesh.positions, mesh.faces, PlyEncoding::BinaryBigEndian);
  const std::string before = read_bytes(file);
  TestMesh bad = mesh;
  bad.positions[0].x() = std::numeric_limits<double>::infinity();
  EXPECT_THROW(write_ply(file, bad.positions, bad.faces), PreconditionError);
  EXPECT_EQ(read_bytes(file), before);
  std::size_t entries = 0;
  for (const auto& entry : fs::directory_iterator(dir.path())) {
    ++entries;
    EXPECT_EQ(entry.path().filename(), "m.ply");
  }
  EXPECT_EQ(entries, 1u);
  // A folder that does not exist: ParseError naming the file.
  const fs::path nowhere = dir / "no/such/folder/m.obj";
  expect_parse_error([&] { write_obj(nowhere, mesh.positions, mesh.faces); }, nowhere,
                     At::Nowhere(), "");
}

TEST(Writers, TextIsShortestExactDecimal) {
  TempDir dir;
  const Positions p = {Vec3(0.1, -0.0, 1.0 / 3.0), Vec3(1e300, 5e-324, 2), Vec3(0, 0, 1)};
  const std::vector<Face> f = {{0, 1, 2}};
  write_obj(dir / "m.obj", p, f);
  const std::string text = read_bytes(dir / "m.obj");
  EXPECT_NE(text.find("v 0.1 -0 0.3333333333333333\n"), std::string::npos) << text;
  EXPECT_NE(text.find("v 1e+300 5e-324 2\n"), std::string::npos) << text;
  EXPECT_NE(text.find("f 1 2 3\n"), std::string::npos) << text;
}

}  // namespace
}  // namespace crumple::io::test
