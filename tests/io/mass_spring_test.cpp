// The X3D MassSpring node: full lists, the short-list rule (repeat the last value), defaults,
// the Face extension, exact round trips, and the errors it reports.

#include "io_test_util.hpp"

#include <crumple/io/x3d.hpp>

namespace crumple::io::test {
namespace {

std::string document(const std::string& mass_spring_content) {
  return "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n"  // line 1
         "<X3D><Scene><StaticGroup><Shape>\n"             // line 2
         "<MassSpring ccw=\"FALSE\" convex=\"false\" solid=\"false\">\n" +  // line 3
         mass_spring_content +                                              // from line 4
         "</MassSpring>\n</Shape></StaticGroup></Scene></X3D>\n";
}

MassSpringData read_text(const TempDir& dir, const std::string& text,
                         const MassSpringDefaults& defaults = {}) {
  write_bytes(dir / "ms.x3d", text);
  return read_mass_spring(dir / "ms.x3d", defaults);
}

TEST(MassSpring, FullLists) {
  TempDir dir;
  const MassSpringData d = read_text(
      dir, document("<Vertex point='0 0 0, 1 0 0, 0 1 0, 1 1 0' mass='0 1000 2 3'\n"
                    "        velocity='0.1 0.1 0.1, 0 0 0, 1 2 3, -1 -2 -3'/>\n"
                    "<Edge vertex='0 1, 1 2, 2 0, 1 3, 3 2' stiffness='5000 20000 1 2 3'\n"
                    "      dampingRatio='0.1 0.2 0.3 0.4 0.5' length='1 2 3 4 5'/>\n"
                    "<Face vertex='0 1 2, 2 1 3'/>\n"));
  EXPECT_EQ(d.positions, (Positions{Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0), Vec3(1, 1, 0)}));
  EXPECT_EQ(d.masses, (std::vector<Scalar>{0, 1000, 2, 3}));  // mass 0: a pinned vertex, kept as 0
  EXPECT_EQ(d.velocities,
            (Positions{Vec3(0.1, 0.1, 0.1), Vec3(0, 0, 0), Vec3(1, 2, 3), Vec3(-1, -2, -3)}));
  EXPECT_EQ(d.springs, (std::vector<Edge>{{0, 1}, {1, 2}, {2, 0}, {1, 3}, {3, 2}}));
  EXPECT_EQ(d.stiffness, (std::vector<Scalar>{5000, 20000, 1, 2, 3}));
  EXPECT_EQ(d.damping_ratio, (std::vector<Scalar>{0.1, 0.2, 0.3, 0.4, 0.5}));
  EXPECT_EQ(d.rest_length, (std::vector<Scalar>{1, 2, 3, 4, 5}));
  EXPECT_EQ(d.faces, (std::vector<Face>{{0, 1, 2}, {2, 1, 3}}));
}

TEST(MassSpring, ShortListsRepeatTheLastValue) {
  TempDir dir;
  const MassSpringData d = read_text(
      dir, document("<Vertex point='0 0 0, 1 0 0, 0 1 0, 1 1 0' mass='0 7' velocity='0 0 1'/>\n"
                    "<Edge vertex='0 1, 1 2, 2 0' stiffness='5000' dampingRatio='0.1 0.2'\n"
                    "      length='1 2'/>\n"));
  EXPECT_EQ(d.masses, (std::vector<Scalar>{0, 7, 7, 7}));
  EXPECT_EQ(d.velocities, Positions(4, Vec3(0, 0, 1)));
  EXPECT_EQ(d.stiffness, (std::vector<Scalar>{5000, 5000, 5000}));
  EXPECT_EQ(d.damping_ratio, (std::vector<Scalar>{0.1, 0.2, 0.2}));
  EXPECT_EQ(d.rest_length, (std::vector<Scalar>{1, 2, 2}));
  EXPECT_TRUE(d.faces.empty());
}

TEST(MassSpring, AbsentOrEmptyListsUseTheDefaults) {
  TempDir dir;
  const std::string text = document(
      "<Vertex point='0 0 0, 3 0 0, 0 4 0' mass=''/>\n"
      "<Edge vertex='0 1, 1 2, 2 0' dampingRatio=' '/>\n");
  const MassSpringData d = read_text(dir, text);
  EXPECT_EQ(d.masses, (std::vector<Scalar>{1, 1, 1}));
  EXPECT_EQ(d.velocities, Positions(3, Vec3::Zero()));
  EXPECT_EQ(d.stiffness, (std::vector<Scalar>{1000, 1000, 1000}));
  EXPECT_EQ(d.damping_ratio, (std::vector<Scalar>{0.1, 0.1, 0.1}));
  // Rest lengths: the distances at load.
  EXPECT_EQ(d.rest_length, (std::vector<Scalar>{3, 5, 4}));

  const MassSpringData custom = read_text(dir, text, {.mass = 2, .stiffness = 30, .damping_ratio = 0.5});
  EXPECT_EQ(custom.masses, (std::vector<Scalar>{2, 2, 2}));
  EXPECT_EQ(custom.stiffness, (std::vector<Scalar>{30, 30, 30}));
  EXPECT_EQ(custom.damping_ratio, (std::vector<Scalar>{0.5, 0.5, 0.5}));

  // No Edge node: no springs.
  const MassSpringData points = read_text(dir, document("<Vertex point='0 0 0'/>\n"));
  EXPECT_EQ(points.positions.size(), 1u);
  EXPECT_TRUE(points.springs.empty());
  EXPECT_TRUE(points.stiffness.empty());
}

TEST(MassSpring, ReadX3dGivesPositionsAndFaces) {
  TempDir dir;
  write_bytes(dir / "ms.x3d", document("<Vertex point='0 0 0, 1 0 0, 0 1 0, 1 1 0'/>\n"
                                       "<Edge vertex='0 1'/>\n"
                                       "<Face vertex='0 1 2 2 1 3'/>\n"));
  const MeshData m = read_x3d(dir / "ms.x3d");
  EXPECT_EQ(m.positions.size(), 4u);
  EXPECT_EQ(m.faces, (std::vector<Face>{{0, 1, 2}, {2, 1, 3}}));
  const TriMesh tri = read_mesh(dir / "ms.x3d");
  EXPECT_EQ(tri.num_faces(), 2);
}

MassSpringData random_system(std::uint64_t seed) {
  const TestMesh mesh = awkward_mesh(6, seed);
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  MassSpringData d;
  d.positions = mesh.positions;
  d.faces = mesh.faces;
  for (std::size_t v = 0; v < d.positions.size(); ++v) {
    d.masses.push_back(v % 5 == 0 ? 0.0 : u(rng) * 1e3);
    d.velocities.push_back(Vec3(u(rng) - 0.5, -0.0, u(rng) * 1e-7));
  }
  for (const Face& f : d.faces) {
    for (int k = 0; k < 3; ++k) {
      d.springs.push_back({f[static_cast<std::size_t>(k)], f[static_cast<std::size_t>((k + 1) % 3)]});
      d.stiffness.push_back(u(rng) * 1e5);
      d.damping_ratio.push_back(u(rng));
      d.rest_length.push_back(u(rng) / 3);
    }
  }
  return d;
}

void expect_same(const MassSpringData& a, const MassSpringData& b) {
  EXPECT_TRUE(same_bits(a.positions, b.positions));
  EXPECT_TRUE(same_bits(a.velocities, b.velocities));
  EXPECT_EQ(a.masses, b.masses);
  EXPECT_EQ(a.springs, b.springs);
  EXPECT_EQ(a.stiffness, b.stiffness);
  EXPECT_EQ(a.damping_ratio, b.damping_ratio);
  EXPECT_EQ(a.rest_length, b.rest_length);
  EXPECT_EQ(a.faces, b.faces);
}

TEST(MassSpring, RoundTripIsExact) {
  TempDir dir;
  for (std::uint64_t seed = 1; seed <= 10; ++seed) {
    SCOPED_TRACE(seed);
    const MassSpringData d = random_system(seed);
    write_mass_spring(dir / "ms.x3d", d);
    expect_same(read_mass_spring(dir / "ms.x3d"), d);
  }
  // Empty lists round-trip too.
  MassSpringData empty;
  empty.positions = {Vec3(1, 2, 3)};
  empty.masses = {0};
  empty.velocities = {Vec3::Zero()};
  write_mass_spring(dir / "empty.x3d", empty);
  expect_same(read_mass_spring(dir / "empty.x3d"), empty);
}

TEST(MassSpring, WriterChecksItsArguments) {
  TempDir dir;
  const MassSpringData good = random_system(3);
  const auto expect_rejected = [&](const std::function<void(MassSpringData&)>& spoil) {
    MassSpringData d = good;
    spoil(d);
    EXPECT_THROW(write_mass_spring(dir / "bad.x3d", d), PreconditionError);
  };
  expect_rejected([](MassSpringData& d) { d.masses.pop_back(); });
  expect_rejected([](MassSpringData& d) { d.velocities.push_back(Vec3::Zero()); });
  expect_rejected([](MassSpringData& d) { d.stiffness.pop_back(); });
  expect_rejected([](MassSpringData& d) { d.rest_length.clear(); });
  expect_rejected([](MassSpringData& d) { d.masses[1] = -1; });
  expect_rejected([](MassSpringData& d) { d.damping_ratio[0] = std::nan(""); });
  expect_rejected([](MassSpringData& d) { d.springs[2] = {1, 1}; });
  expect_rejected([](MassSpringData& d) { d.springs[2] = {1, 1000}; });
  expect_rejected([](MassSpringData& d) { d.faces[0][0] = 1000; });
  EXPECT_FALSE(fs::exists(dir / "bad.x3d"));
}

TEST(MassSpring, Errors) {
  TempDir dir;
  const fs::path file = dir / "bad.x3d";
  const std::string vertex = "<Vertex point='0 0 0, 1 0 0, 0 1 0'/>\n";  // line 4
  struct Case {
    std::string text;
    std::int64_t line;
    std::string needle;
  };
  const std::vector<Case> cases = {
      {"<X3D><Scene><Shape><IndexedFaceSet/></Shape></Scene></X3D>", 1, "no <MassSpring> node"},
      {document(""), 3, "<MassSpring> has no <Vertex"},
      {document("<Vertex/>\n"), 4, "<Vertex> has no 'point' attribute"},
      {document(vertex + vertex), 5, "a second <Vertex> in <MassSpring>"},
      {document("<Vertex point='0 0 0, 1 0'/>\n"), 4, "<Vertex point>: has 5 numbers"},
      {document("<Vertex point='0 0 0, 1 0 0' mass='1 2 3'/>\n"), 4,
       "<Vertex mass>: has 3 values but there are only 2 vertices"},
      {document("<Vertex point='0 0 0, 1 0 0' mass='1 heavy'/>\n"), 4,
       "<Vertex mass>: value 1 is 'heavy', expected a number"},
      {document("<Vertex point='0 0 0, 1 0 0' mass='1 -2'/>\n"), 4, "value 1 ('-2') is negative"},
      {document("<Vertex point='0 0 0, 1 0 0' mass='inf'/>\n"), 4, "is not finite"},
      {document("<Vertex point='0 0 0, 1 0 0' velocity='1 2'/>\n"), 4,
       "<Vertex velocity>: has 2 numbers, expected x y z triples"},
      {document("<Vertex point='0 0 0, 1 0 0' velocity='1 2 3, 4 5 6, 7 8 9'/>\n"), 4,
       "<Vertex velocity>: has 3 values but there are only 2 vertices"},
      {document(vertex + "<Edge vertex='0 1, 1'/>\n"), 5, "<Edge vertex>: has 3 vertex ids, expected 2 per spring"},
      {document(vertex + "<Edge vertex='0 1, 1 3'/>\n"), 5, "spring 1 has vertex id 3 outside [0, 3)"},
      {document(vertex + "<Edge vertex='0 1, -1 2'/>\n"), 5, "spring 1 has vertex id -1"},
      {document(vertex + "<Edge vertex='0 1, 2 2'/>\n"), 5, "spring 1 joins vertex 2 to itself"},
      {document(vertex + "<Edge vertex='0 1, 1 x'/>\n"), 5, "value 3 is 'x', expected an integer"},
      {document(vertex + "<Edge vertex='0 1' stiffness='1 2'/>\n"), 5,
       "<Edge stiffness>: has 2 values but there are only 1 springs"},
      {document(vertex + "<Edge vertex='0 1' dampingRatio='-0.5'/>\n"), 5, "negative"},
      {document(vertex + "<Edge vertex='0 1' length='1 2'/>\n"), 5, "<Edge length>: has 2 values"},
      {document(vertex + "<Edge vertex='0 1'/>\n<Edge vertex='1 2'/>\n"), 6, "a second <Edge>"},
      {document(vertex + "<Face vertex='0 1 2, 0 1'/>\n"), 5, "<Face vertex>: has 5 vertex ids, expected 3 per triangle"},
      {document(vertex + "<Face vertex='0 1 3'/>\n"), 5, "triangle 0 has vertex id 3 outside [0, 3)"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.needle);
    write_bytes(file, c.text);
    expect_parse_error([&] { read_mass_spring(file); }, file, At::Line(c.line), c.needle);
  }
}

TEST(MassSpring, TruncatedFilesAreRejected) {
  TempDir dir;
  const fs::path file = dir / "cut.x3d";
  MassSpringData d = random_system(1);
  d.positions.resize(4);
  d.masses.resize(4);
  d.velocities.resize(4);
  d.faces = {{0, 1, 2}};
  d.springs = {{0, 1}, {1, 2}};
  d.stiffness.resize(2);
  d.damping_ratio.resize(2);
  d.rest_length.resize(2);
  write_mass_spring(file, d);
  const std::string full = read_bytes(file);
  for (const std::size_t cut : cut_points(full.size(), 5)) {
    write_bytes(file, full.substr(0, cut));
    try {
      const MassSpringData back = read_mass_spring(file);
      EXPECT_GE(cut, full.rfind("</X3D>") + 6) << "cut at " << cut << " was accepted";
    } catch (const ParseError& e) {
      EXPECT_EQ(e.file(), file.string());
      EXPECT_TRUE(e.line().has_value()) << e.what();
    }
  }
}

}  // namespace
}  // namespace crumple::io::test
