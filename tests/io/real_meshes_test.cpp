// The real meshes of CRUMPLE_DATA_DIR (see its README.md): exact counts, spot checks of the
// first and last vertex and face, and a checksum of every coordinate and id.
//
// Expected values were decoded independently of crumple with Python's `struct` module (header
// parsed by hand, body read with struct.unpack_from in the file's byte order), then printed with
// repr(), which gives the shortest text that reads back to the same double:
//   coordinate_sum = 0.0; for v in vertices: for c in (x, y, z): coordinate_sum += c
//   id_checksum = sum over faces f, corners k of f[k] * (k + 1)      (exact integer)
// The C++ side sums in the same order, so the doubles must match bit for bit.

#include "io_test_util.hpp"
#include "support/meshes.hpp"

#include <chrono>
#include <cstdlib>

namespace crumple::io::test {
namespace {

struct RealMesh {
  const char* file;  // relative to CRUMPLE_DATA_DIR
  std::size_t vertices;
  std::size_t faces;
  Vec3 first_vertex;
  Vec3 last_vertex;
  Face first_face;
  Face last_face;
  double coordinate_sum;
  std::int64_t id_checksum;
};

const RealMesh real_meshes[] = {
    {"ipc-toolkit-tests/bunny.ply", 2503, 5002, {-0.374219, 0.60416, 0.050243},
     {-0.211108, 0.134371, 0.097101}, {0, 1, 2}, {2494, 2401, 2173}, 820.5558220000019, 37316758},
    {"ipc-toolkit-tests/cube.ply", 8, 12, {-0.5, -0.5, -0.5}, {0.5, -0.5, 0.5}, {0, 1, 2}, {5, 6, 4},
     0.0, 280},
    {"ipc-toolkit-tests/height-field.ply", 2540, 4904, {0.812862, 0.037917, -0.812806},
     {0.9953616249999999, 0.0, 0.8625491249999999}, {1825, 1, 2}, {2077, 2539, 1695},
     235.04494256250018, 33004766},
    {"ipc-toolkit-tests/two-cubes-close.ply", 262, 480, {0.0, 0.15467947383035, 0.15467947383035},
     {1.00174427720724, -0.013474285725655, -0.0095788014677523}, {39, 55, 11}, {190, 261, 134},
     473.07092486181386, 390310},
    {"ipc-toolkit-tests/two-cubes-far.ply", 262, 480, {0.0, 0.15467947383035, 0.15467947383035},
     {1.5, 0.0, 0.0}, {39, 11, 55}, {190, 134, 261}, 547.4311672037223, 393459},
    {"ipc-toolkit-tests/two-cubes-intersecting.ply", 262, 480,
     {0.0, 0.15467947383035, 0.15467947383035},
     {0.90174427720724, -0.013474285725655, -0.0095788014677523}, {39, 55, 11}, {190, 261, 134},
     460.8709248618131, 390310},
    {"ipc-toolkit-tests/thick-cloth/t0.ply", 233, 404, {-2.5, 0.0, -2.5}, {15.0, 2.02683, 15.0},
     {0, 3, 2}, {216, 232, 231}, 972.8697500000012, 288602},
    {"ipc-toolkit-tests/thick-cloth/t1.ply", 233, 404, {-2.5, 0.0, -2.5}, {15.0, 1.44994, 15.0},
     {0, 3, 2}, {216, 232, 231}, 861.8974200000004, 288602},
    {"sample-scalable-ccd/armadillo-rollers/frames/326.ply", 12135, 24242,
     {-0.666668993554034, 1.0000019790508, -0.824555},
     {0.265353791291653, 0.251068325471585, 0.400092751539763}, {0, 273, 264}, {12133, 3479, 3400},
     6145.541317239962, 811898371},
    {"sample-scalable-ccd/armadillo-rollers/frames/327.ply", 12135, 24242,
     {-0.666669033065748, 1.00000223034509, -0.824555},
     {0.287123981472346, 0.309044635220288, 0.485360479972181}, {0, 273, 264}, {12133, 3479, 3400},
     6000.348915232823, 811898371},
    {"sample-scalable-ccd/cloth-ball/frames/cloth_ball92.ply", 46598, 92230,
     {5.388155937194824, 0.4000000059604645, -13.101426124572754}, {0.0, 11.676539421081543, 0.0},
     {728, 729, 3488}, {46595, 46576, 46597}, 119310.13015963626, 12614312992},
    {"sample-scalable-ccd/cloth-ball/frames/cloth_ball93.ply", 46598, 92230,
     {5.120972156524658, 0.4000000059604645, -13.01651668548584}, {0.0, 11.696081161499023, 0.0},
     {728, 729, 3488}, {46595, 46576, 46597}, 119735.13404831389, 12614312992},
    {"sample-scalable-ccd/cloth-funnel/frames/227.ply", 9450, 18484,
     {-0.002984900027513504, 0.04871189966797829, -0.4281400144100189}, {1.25, -1.25, -2.0},
     {7333, 7335, 24}, {9448, 9438, 9437}, -3726.643600775335, 538744605},
    {"sample-scalable-ccd/cloth-funnel/frames/228.ply", 9450, 18484,
     {-0.003333060070872307, 0.048372700810432434, -0.4313740134239197}, {1.25, -1.25, -2.0},
     {7333, 7335, 24}, {9448, 9438, 9437}, -3751.12456425253, 538744605},
    {"sample-scalable-ccd/n-body-simulation/frames/balls16_18.ply", 73960, 146480,
     {3.903536319732666, 2.9625191688537598, -1.0990840196609497},
     {3.461939811706543, 0.0, 2.8086583614349365}, {0, 1, 2}, {73944, 73928, 73943},
     384377.3444483344, 32453267920},
    {"sample-scalable-ccd/n-body-simulation/frames/balls16_19.ply", 73960, 146480,
     {3.7566795349121094, 3.057393789291382, -1.3671327829360962},
     {3.461939811706543, 0.0, 2.8086583614349365}, {0, 1, 2}, {73944, 73928, 73943},
     384453.8214850209, 32453267920},
    {"sample-scalable-ccd/rod-twist/frames/3036.ply", 39940, 79864,
     {-0.000669337430715617, -0.0122770066347049, 0.146721039461198},
     {0.999297011136861, 0.0783786051798172, 0.272398841799126}, {0, 103, 117},
     {39938, 39920, 29985}, 28680.856676568423, 9568968036},
    {"sample-scalable-ccd/rod-twist/frames/3037.ply", 39940, 79864,
     {-0.000669305414310962, -0.0113713060721253, 0.150863227230739},
     {0.999297053099046, 0.073609267114767, 0.271017086225985}, {0, 103, 117},
     {39938, 39920, 29985}, 28684.559425496976, 9568968036},
};

using crumple::testing::data_dir;  // the environment's CRUMPLE_DATA_DIR, else the configured folder

// Fails (does not skip) when the shared data is missing: these checks must not pass silently.
::testing::AssertionResult data_available() {
  if (!fs::is_directory(data_dir())) {
    return ::testing::AssertionFailure()
           << "CRUMPLE_DATA_DIR = " << data_dir()
           << " does not exist: the real-mesh tests need the shared data folder "
              "(configure with -DCRUMPLE_DATA_DIR=/path/to/shared/data or set the environment "
              "variable CRUMPLE_DATA_DIR)";
  }
  return ::testing::AssertionSuccess();
}

// `CRUMPLE_DATA_DIR=/elsewhere ctest` reached this program only (the other test programs read
// the configured folder alone): every test program's `data_path` follows the environment, and
// an empty value means the configured folder.
TEST(RealMeshes, TheEnvironmentMovesEveryTestProgramsDataFolder) {
  const char* was = std::getenv("CRUMPLE_DATA_DIR");
  const std::string saved = was != nullptr ? was : "";
  ::setenv("CRUMPLE_DATA_DIR", "/elsewhere/data", 1);
  EXPECT_EQ(crumple::testing::data_path("a/t0.ply"), fs::path("/elsewhere/data/a/t0.ply"));
  ::setenv("CRUMPLE_DATA_DIR", "", 1);
  EXPECT_EQ(crumple::testing::data_path("a/t0.ply"), fs::path(CRUMPLE_DATA_DIR) / "a/t0.ply");
  ::unsetenv("CRUMPLE_DATA_DIR");
  EXPECT_EQ(data_dir(), fs::path(CRUMPLE_DATA_DIR));
  if (was != nullptr) ::setenv("CRUMPLE_DATA_DIR", saved.c_str(), 1);
}

TEST(RealMeshes, EveryPlyFileIsListed) {
  ASSERT_TRUE(data_available());
  std::size_t found = 0;
  for (const auto& entry : fs::recursive_directory_iterator(data_dir())) {
    if (entry.path().extension() != ".ply") continue;
    ++found;
    const fs::path relative = fs::relative(entry.path(), data_dir());
    bool listed = false;
    for (const RealMesh& m : real_meshes) listed = listed || relative == fs::path(m.file);
    EXPECT_TRUE(listed) << relative << " has no expected counts in this test";
  }
  EXPECT_EQ(found, std::size(real_meshes));
}

TEST(RealMeshes, CountsValuesAndChecksums) {
  ASSERT_TRUE(data_available());
  for (const RealMesh& expected : real_meshes) {
    SCOPED_TRACE(expected.file);
    const MeshData m = read_ply(data_dir() / expected.file);
    ASSERT_EQ(m.positions.size(), expected.vertices);
    ASSERT_EQ(m.faces.size(), expected.faces);
    EXPECT_EQ(m.positions.front(), expected.first_vertex);
    EXPECT_EQ(m.positions.back(), expected.last_vertex);
    EXPECT_EQ(m.faces.front(), expected.first_face);
    EXPECT_EQ(m.faces.back(), expected.last_face);
    double sum = 0;
    for (const Vec3& p : m.positions) {
      for (int k = 0; k < 3; ++k) sum += p[k];
    }
    EXPECT_EQ(sum, expected.coordinate_sum);
    std::int64_t ids = 0;
    for (const Face& f : m.faces) {
      for (int k = 0; k < 3; ++k) ids += std::int64_t{f[static_cast<std::size_t>(k)]} * (k + 1);
    }
    EXPECT_EQ(ids, expected.id_checksum);
  }
}

TEST(RealMeshes, ValidateAsTriMeshes) {
  ASSERT_TRUE(data_available());
  for (const char* file : {"ipc-toolkit-tests/bunny.ply", "sample-scalable-ccd/cloth-funnel/frames/227.ply",
                           "sample-scalable-ccd/armadillo-rollers/frames/326.ply"}) {
    SCOPED_TRACE(file);
    const TriMesh mesh = read_mesh(data_dir() / file);
    EXPECT_GT(mesh.num_faces(), 0);
  }
}

TEST(RealMeshes, BiggestFileReadsFast) {
  ASSERT_TRUE(data_available());
  const fs::path file = data_dir() / "sample-scalable-ccd/n-body-simulation/frames/balls16_18.ply";
  double best = 1e9;
  for (int run = 0; run < 3; ++run) {
    const auto start = std::chrono::steady_clock::now();
    const MeshData m = read_ply(file);
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    best = std::min(best, seconds);
    ASSERT_EQ(m.faces.size(), 146480u);
  }
  RecordProperty("read_seconds", std::to_string(best));
  std::cout << "[ info ] n-body frame (146,480 faces, big-endian) read in " << best * 1e3 << " ms\n";
#if defined(NDEBUG) && !defined(__SANITIZE_ADDRESS__)
  EXPECT_LT(best, 0.5) << "reading the biggest PLY should take well under a second";
#endif
}

TEST(RealMeshes, SurviveARoundTripThroughEveryFormat) {
  ASSERT_TRUE(data_available());
  const MeshData original = read_ply(data_dir() / "sample-scalable-ccd/armadillo-rollers/frames/326.ply");
  TempDir dir;
  for (const char* name : {"a.obj", "a.off", "a.x3d", "a.ply"}) {
    SCOPED_TRACE(name);
    write_mesh(dir / name, original.positions, original.faces);
    const MeshData back = read_mesh_data(dir / name);
    EXPECT_TRUE(same_bits(back.positions, original.positions));
    EXPECT_EQ(back.faces, original.faces);
  }
  write_ply(dir / "b.ply", original.positions, original.faces, PlyEncoding::Ascii);
  const MeshData ascii = read_ply(dir / "b.ply");
  EXPECT_TRUE(same_bits(ascii.positions, original.positions));
  EXPECT_EQ(ascii.faces, original.faces);
}

}  // namespace
}  // namespace crumple::io::test
