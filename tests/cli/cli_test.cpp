// Runs the `crumple` binary as a user would and checks what it prints and writes.
#include <crumple/core/parallel.hpp>
#include <crumple/io/mesh_io.hpp>
#include <support/meshes.hpp>
#include <support/oracle.hpp>
#include <support/run_cli.hpp>
#include <support/temp_dir.hpp>

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstdlib>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <sstream>
#include <string>
#include <sys/wait.h>
#include <unistd.h>

namespace crumple {
namespace {

using Result = testing::CliResult;

Result run(const std::string& args) { return testing::run_cli(args); }

std::string funnel(int frame) {
  return testing::data_path("sample-scalable-ccd/cloth-funnel/frames/" + std::to_string(frame) + ".ply").string();
}

TEST(Cli, HelpListsCommandsAndMethods) {
  Result r = run("--help");
  EXPECT_EQ(r.status, 0) << r.out;
  EXPECT_NE(r.out.find("detect"), std::string::npos);
  EXPECT_NE(r.out.find("info"), std::string::npos);
  r = run("detect --help");
  EXPECT_EQ(r.status, 0) << r.out;
  EXPECT_NE(r.out.find("naive"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("--thickness-rel"), std::string::npos);
}

TEST(Cli, DetectOnBuiltInSceneFindsContacts) {
  const Result r = run("detect");
  ASSERT_EQ(r.status, 0) << r.out;
  EXPECT_NE(r.out.find("builtin:folded-cloth"), std::string::npos) << r.out;
  EXPECT_EQ(r.out.find("vf 0 "), std::string::npos) << r.out;
}

TEST(Cli, BadInputGivesOneLineErrorAndNonZeroExit) {
  const testing::TempDir dir;
  std::ofstream(dir / "broken.obj") << "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n";
  Result r = run("detect " + (dir / "broken.obj").string());
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.out.find("broken.obj:4"), std::string::npos) << r.out;
  r = run("detect --method bogus");
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.out.find("valid: naive"), std::string::npos) << r.out;
  r = run("detect --method naive:x=1");
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.out.find("unknown key 'x'"), std::string::npos) << r.out;
  r = run("detect --kinds vf,zz");
  EXPECT_NE(r.status, 0);
  r = run("detect " + (dir / "missing.ply").string());
  EXPECT_NE(r.status, 0);
  r = run("detect --thickness 1 --thickness-rel 0.1");
  EXPECT_NE(r.status, 0) << "the two thickness options exclude each other";
  r = run("info " + (dir / "broken.obj").string());
  EXPECT_NE(r.status, 0);
}

// `crumple detect` with CRUMPLE_PARALLEL set (inherited by the program) to `value`.
Result detect_with_backend(const char* value, const std::string& args) {
  ::setenv("CRUMPLE_PARALLEL", value, 1);
  Result r = run("detect " + args);
  ::unsetenv("CRUMPLE_PARALLEL");
  return r;
}

TEST(Cli, ParallelBackendFromTheEnvironment) {
  // A bad value is a user error naming it, even on one thread (no loop runs in parallel).
  for (const char* threads : {"1", "2"}) {
    const Result r = detect_with_backend("bogus", std::string("--method kdop --threads ") + threads);
    EXPECT_EQ(r.status, 1) << r.out;
    EXPECT_NE(r.out.find("crumple: error: CRUMPLE_PARALLEL='bogus': expected 'team' or 'tbb'"), std::string::npos)
        << r.out;
  }
  // Both backends find the same contacts: the frame line's "vf N  ee N  tt N" (then its time).
  const auto counts = [](const Result& r) {
    std::istringstream line(r.out.substr(r.out.find("frame 0")));
    std::string word, counted;
    for (int k = 0; k < 9 && line >> word; ++k) counted += word + " ";
    return counted;
  };
  const Result team = detect_with_backend("team", "--method kdop --threads 2");
  ASSERT_EQ(team.status, 0) << team.out;
  EXPECT_NE(counts(team).find(" vf "), std::string::npos) << team.out;
  if (has_parallel_backend(ParallelBackend::tbb)) {
    const Result tbb = detect_with_backend("tbb", "--method kdop --threads 2");
    ASSERT_EQ(tbb.status, 0) << tbb.out;
    EXPECT_EQ(counts(tbb), counts(team));
  }
}

TEST(Cli, InfoPrintsCountsAndReport) {
  const Result r = run("info " + funnel(227));
  ASSERT_EQ(r.status, 0) << r.out;
  EXPECT_NE(r.out.find("vertices: 9450"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("faces: 18484"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("edge length min/mean/max"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("non-manifold edges: "), std::string::npos) << r.out;
}

TEST(Cli, JsonHasOneObjectPerFrameWithStats) {
  const testing::TempDir dir;
  const TriMesh m = shapes::folded_cloth({.n = 10});
  io::write_obj(dir / "a.obj", m.positions(), m.topology().faces());
  io::write_obj(dir / "b.obj", testing::jitter(m.positions(), 0.002, 5), m.topology().faces());
  const Result r = run("detect --json --thickness 0.02 " + (dir / "a.obj").string() + " " +
                       (dir / "b.obj").string() + " --contacts " + (dir / "out").string());
  ASSERT_EQ(r.status, 0) << r.out;
  std::istringstream lines(r.out);
  std::string line;
  int frames = 0;
  while (std::getline(lines, line)) {
    ASSERT_EQ(line.front(), '{') << line;
    ASSERT_EQ(line.back(), '}') << line;
    for (const char* key : {"\"frame\":", "\"file\":", "\"vf\":", "\"ee\":", "\"tt\":", "\"ms\":", "\"stats\":{"})
      EXPECT_NE(line.find(key), std::string::npos) << key << " in " << line;
    EXPECT_NE(line.find("\"frame\":" + std::to_string(frames)), std::string::npos) << line;
    ++frames;
  }
  EXPECT_EQ(frames, 2);
  EXPECT_TRUE(std::filesystem::exists(dir / "out" / "a.tsv"));
  EXPECT_TRUE(std::filesystem::exists(dir / "out" / "b.tsv"));
}

TEST(Cli, FramesWithDifferentConnectivityAreRejected) {
  const testing::TempDir dir;
  const TriMesh a = shapes::lattice(3, 3), b = shapes::lattice(4, 2);
  io::write_obj(dir / "a.obj", a.positions(), a.topology().faces());
  io::write_obj(dir / "b.obj", b.positions(), b.topology().faces());
  const Result r = run("detect " + (dir / "a.obj").string() + " " + (dir / "b.obj").string());
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.out.find("b.obj"), std::string::npos) << r.out;
}

// `crumple detect` on mesh files far from unit scale: at 2^1000 and 2^-1000 (squares of the
// coordinates overflow, underflow) the contact lines of unit scale with their distances scaled
// exactly; at 1e300 and 1e-300 (each coordinate rounded once) the same counts of each kind. A
// file whose coordinates span more than the double range is a one-line error, not contacts.
TEST(Cli, DetectAtExtremeScalesGivesTheUnitScaleContacts) {
  const testing::TempDir dir;
  const TriMesh sheet = shapes::lattice(10, 10);
  Positions unit = testing::crumple_lattice(sheet, 0.35, 5);
  for (Vec3& p : unit) p += Vec3::Constant(1.5);
  const auto detect = [&](const std::string& name, const Positions& x, Scalar h) {
    io::write_obj(dir / (name + ".obj"), x, sheet.topology().faces());
    char thickness[32];
    std::snprintf(thickness, sizeof thickness, "%.17g", h);
    const Result r = run("detect --method kdop --kinds vf,ee,tt --thickness " + std::string(thickness) + " " +
                         (dir / (name + ".obj")).string() + " --contacts " + (dir / (name + ".tsv")).string());
    EXPECT_EQ(r.status, 0) << r.out;
    return testing::read_lines(dir / (name + ".tsv"));
  };
  const auto counts = [](const std::vector<std::string>& lines) {
    std::map<std::string, int> n;
    for (const std::string& line : lines) ++n[line.substr(0, 2)];
    return n;
  };
  const Scalar h = 0.03;
  const std::vector<std::string> want = detect("unit", unit, h);
  ASSERT_GT(counts(want)["tt"], 10) << "the scene should touch in every kind";
  ASSERT_GT(counts(want)["vf"], 10);
  for (const int k : {1000, -1000}) {
    SCOPED_TRACE("2^" + std::to_string(k));
    Positions x = unit;
    for (Vec3& p : x) p = Vec3(std::scalbn(p.x(), k), std::scalbn(p.y(), k), std::scalbn(p.z(), k));
    const std::vector<std::string> got = detect("p" + std::to_string(k), x, std::scalbn(h, k));
    ASSERT_EQ(got.size(), want.size());
    for (std::size_t i = 0; i < got.size(); ++i) {
      // Same ids; the distance (last field of vf and ee lines) times 2^k.
      const std::size_t cut = want[i].rfind(' '), got_cut = got[i].rfind(' ');
      if (want[i].starts_with("tt")) {
        EXPECT_EQ(got[i], want[i]);
        continue;
      }
      ASSERT_EQ(got[i].substr(0, got_cut), want[i].substr(0, cut)) << i;
      EXPECT_EQ(std::strtod(got[i].c_str() + got_cut, nullptr),
                std::scalbn(std::strtod(want[i].c_str() + cut, nullptr), k))
          << got[i] << " vs " << want[i];
    }
  }
  for (const Scalar scale : {1e300, 1e-300}) {
    Positions x = unit;
    for (Vec3& p : x) p *= scale;
    EXPECT_EQ(counts(detect(scale > 1 ? "big" : "small", x, h * scale)), counts(want));
  }
  Positions wide = unit;
  for (Vec3& p : wide) p *= 1e300;
  wide[7].y() = 1e-300;
  io::write_obj(dir / "wide.obj", wide, sheet.topology().faces());
  const Result r = run("detect " + (dir / "wide.obj").string());
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.out.find("span more than the double range: vertex 7's y coordinate"), std::string::npos) << r.out;
}

/// The acceptance check: naive on funnel frame 227 at thickness 1e-3 of the diagonal,
/// contacts written to a file, checked against the independent oracle of tests/support.
TEST(Cli, FunnelContactsMatchIndependentOracle) {
  const testing::TempDir dir;
  const auto out = dir / "out.tsv";
  const Result r = run("detect " + funnel(227) + " --thickness-rel 1e-3 --contacts " + out.string());
  ASSERT_EQ(r.status, 0) << r.out;
  std::cout << r.out;

  const TriMesh mesh = io::read_mesh(funnel(227));
  const Scalar h = 1e-3 * compute_bounds(mesh.positions()).diagonal();
  const auto oracle = oracle::brute_force(mesh.topology(), mesh.positions(), h * (1 + 1e-9));
  const long double lo = h * (1 - 1e-9);

  std::ifstream in(out);
  std::string kind;
  std::set<std::pair<Index, Index>> vf_found;
  std::set<std::array<Index, 4>> ee_found;
  while (in >> kind) {
    if (kind == "vf") {
      Index v, f;
      double d;
      in >> v >> f >> d;
      auto it = oracle.vf.find({v, f});
      ASSERT_NE(it, oracle.vf.end()) << "false vf " << v << " " << f;
      EXPECT_NEAR(d, static_cast<double>(it->second), 1e-9 * h);
      EXPECT_TRUE(vf_found.insert({v, f}).second) << "duplicate line";
    } else if (kind == "ee") {
      std::array<Index, 4> k;
      double d;
      in >> k[0] >> k[1] >> k[2] >> k[3] >> d;
      auto it = oracle.ee.find(k);
      ASSERT_NE(it, oracle.ee.end()) << "false ee " << k[0] << " " << k[1] << " " << k[2] << " " << k[3];
      EXPECT_NEAR(d, static_cast<double>(it->second), 1e-9 * h);
      EXPECT_TRUE(ee_found.insert(k).second) << "duplicate line";
    } else {
      FAIL() << "unexpected line kind " << kind;
    }
  }
  for (const auto& [k, d] : oracle.vf) {
    if (d < lo) {
      EXPECT_TRUE(vf_found.count(k)) << "missed vf " << k.first << " " << k.second << " d=" << static_cast<double>(d);
    }
  }
  for (const auto& [k, d] : oracle.ee) {
    if (d < lo) {
      EXPECT_TRUE(ee_found.count(k)) << "missed ee " << k[0] << " " << k[1] << " " << k[2] << " " << k[3];
    }
  }
  std::cout << "funnel 227: " << vf_found.size() << " vf, " << ee_found.size() << " ee (oracle "
            << oracle.vf.size() << ", " << oracle.ee.size() << ")\n";
  EXPECT_GT(vf_found.size() + ee_found.size(), 0u) << "the funnel frame has proximity contacts at 1e-3";
}

}  // namespace
}  // namespace crumple
