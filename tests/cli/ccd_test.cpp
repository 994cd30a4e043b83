// `crumple ccd --queries FILE`: answers per line, exact hex input, δ, and clear errors.
// `crumple ccd FRAME0 FRAME1`: the earliest TOI, impacts files equal for every method,
// mismatched frames and conflicting options named.
#include <gtest/gtest.h>

#include <support/meshes.hpp>
#include <support/run_cli.hpp>
#include <support/temp_dir.hpp>

#include <cstdlib>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

namespace crumple {
namespace {

using testing::run_cli;

std::string write(const testing::TempDir& dir, const std::string& name, const std::string& text) {
  const std::filesystem::path path = dir / name;
  std::ofstream(path) << text;
  return path.string();
}

std::vector<std::string> lines(const std::string& text) {
  std::vector<std::string> out;
  std::istringstream in(text);
  for (std::string l; std::getline(in, l);) out.push_back(l);
  return out;
}

// Vertex falling through the static triangle (0,0,0) (1,0,0) (0,1,0) at t = 1/2; the same
// vertex beside it; edges crossing at t = 1/4 (in hex); a comment and a blank line.
const char* kQueries =
    "# vertex through the triangle\n"
    "vf 0.25 0.25 1  0 0 0  1 0 0  0 1 0   0.25 0.25 -1  0 0 0  1 0 0  0 1 0\n"
    "\n"
    "vf 0.8 0.8 1  0 0 0  1 0 0  0 1 0   0.8 0.8 -1  0 0 0  1 0 0  0 1 0\n"
    "ee -0x1p+0 0 0  0x1p+0 0 0  0 -1 0x1p-2  0 1 0x1p-2   -1 0 0  1 0 0  0 -1 -0x1.8p-1  0 1 -0x1.8p-1\n"
    "vf 0.25 0.25 0.05  0 0 0  1 0 0  0 1 0   0.25 0.25 0.05  0 0 0  1 0 0  0 1 0\n";

TEST(CliCcd, OneAnswerPerQuery) {
  testing::TempDir dir;
  const std::string file = write(dir, "q.txt", kQueries);
  const auto r = run_cli("ccd --queries " + file);
  ASSERT_EQ(r.status, 0) << r.out;
  const std::vector<std::string> out = lines(r.out);
  ASSERT_EQ(out.size(), 4u) << r.out;
  ASSERT_EQ(out[0].substr(0, 2), "1 ");
  const double toi = std::strtod(out[0].c_str() + 2, nullptr);
  EXPECT_LE(toi, 0.5);
  EXPECT_GE(toi, 0.5 - 2e-6);
  EXPECT_EQ(out[1], "0");
  ASSERT_EQ(out[2].substr(0, 2), "1 ");
  const double toi_ee = std::strtod(out[2].c_str() + 2, nullptr);
  EXPECT_LE(toi_ee, 0.25);
  EXPECT_GE(toi_ee, 0.25 - 2e-6);
  EXPECT_EQ(out[3], "0");  // resting 0.05 above the triangle
  // Within δ = 0.1 of the triangle from the start.
  const auto d = run_cli("ccd --min-separation 0.1 --queries " + file);
  ASSERT_EQ(d.status, 0) << d.out;
  EXPECT_EQ(lines(d.out).at(3), "1 0") << d.out;
}

TEST(CliCcd, BadLinesNameTheFileAndLine) {
  testing::TempDir dir;
  const struct {
    const char* text;
    const char* expect;
  } cases[] = {
      {"vf 1 2 3\n", ":1: expected 24 numbers after 'vf', got 3"},
      {"\nxx 1\n", ":2: expected 'vf' or 'ee'"},
      {"ee 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 zz\n", "is not a number: 'zz'"},
      {"ee 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 nan\n", "is not a finite double"},
      {"ee 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 1e999\n", "is not a finite double"},
      {"ee 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 7\n", "expected the end of the line"},
  };
  for (const auto& c : cases) {
    const std::string file = write(dir, "bad.txt", c.text);
    const auto r = run_cli("ccd --queries " + file);
    EXPECT_EQ(r.status, 1) << c.text << r.out;
    EXPECT_NE(r.out.find("bad.txt"), std::string::npos) << r.out;
    EXPECT_NE(r.out.find(c.expect), std::string::npos) << r.out;
  }
  const auto missing = run_cli("ccd --queries " + (dir / "missing.txt").string());
  EXPECT_EQ(missing.status, 1) << missing.out;
  EXPECT_NE(missing.out.find("cannot open"), std::string::npos) << missing.out;
}

// A triangle at rest in z = 0 and a small triangle falling through it from z = 10 to z = -10.
std::string falling(double z, bool extra_vertex = false, bool other_faces = false) {
  std::ostringstream out;
  out << "v 0 0 0\nv 1 0 0\nv 0 1 0\n";
  out << "v 0.2 0.2 " << z << "\nv 0.3 0.2 " << z << "\nv 0.2 0.3 " << z << "\n";
  if (extra_vertex) out << "v 5 5 5\n";
  out << (other_faces ? "f 1 3 2\n" : "f 1 2 3\n") << "f 4 5 6\n";
  return out.str();
}

TEST(CliCcd, TwoFramesGiveTheEarliestTimeOfImpact) {
  testing::TempDir dir;
  const std::string f0 = write(dir, "a0.obj", falling(10)), f1 = write(dir, "a1.obj", falling(-10));
  const std::string impacts = (dir / "impacts.txt").string();
  const auto r = run_cli("ccd " + f0 + " " + f1 + " --impacts " + impacts);
  ASSERT_EQ(r.status, 0) << r.out;
  const auto at = r.out.find("earliest toi ");
  ASSERT_NE(at, std::string::npos) << r.out;
  const double toi = std::strtod(r.out.c_str() + at + 13, nullptr);
  EXPECT_LE(toi, 0.5);
  EXPECT_GE(toi, 0.5 - 2e-6);
  EXPECT_NE(r.out.find("impacts vf 3 ee 0"), std::string::npos) << r.out;
  const std::vector<std::string> lines = testing::read_lines(impacts);
  ASSERT_EQ(lines.size(), 3u);
  EXPECT_EQ(lines[0].substr(0, 7), "vf 3 0 ");
  // JSON, one object.
  const auto j = run_cli("ccd " + f0 + " " + f1 + " --json --method sap -j 1");
  ASSERT_EQ(j.status, 0) << j.out;
  EXPECT_EQ(j.out.front(), '{');
  EXPECT_NE(j.out.find("\"vf_impacts\":3"), std::string::npos) << j.out;
  EXPECT_NE(j.out.find("\"earliest_toi\":0.49"), std::string::npos) << j.out;
  // Resting frames: the full step.
  const auto rest = run_cli("ccd " + f0 + " " + f0);
  ASSERT_EQ(rest.status, 0) << rest.out;
  EXPECT_NE(rest.out.find("earliest toi 1 (no impact: full step)"), std::string::npos) << rest.out;
}

TEST(CliCcd, EveryMethodAndThreadCountWritesTheSameImpacts) {
  const std::string f0 = testing::data_path("ipc-toolkit-tests/thick-cloth/t0.ply").string();
  const std::string f1 = testing::data_path("ipc-toolkit-tests/thick-cloth/t1.ply").string();
  testing::TempDir dir;
  std::vector<std::string> reference;
  for (const char* method : {"kdop", "hash", "sap"}) {
    for (const char* threads : {"1", "3"}) {
      const std::string out = (dir / (std::string(method) + threads + ".txt")).string();
      const auto r = run_cli("ccd " + f0 + " " + f1 + " --min-separation-rel 0.01 --method " + method + " -j " +
                             threads + " --impacts " + out);
      ASSERT_EQ(r.status, 0) << r.out;
      const std::vector<std::string> lines = testing::read_lines(out);
      if (reference.empty()) {
        reference = lines;
        EXPECT_FALSE(reference.empty()) << "δ = 1% of the diagonal must give impacts";
      }
      EXPECT_EQ(lines, reference) << method << " threads " << threads;
    }
  }
}

TEST(CliCcd, MismatchedFramesAndBadOptionsAreErrors) {
  testing::TempDir dir;
  const std::string f0 = write(dir, "a0.obj", falling(10));
  const std::string more = write(dir, "more.obj", falling(-10, true));
  const std::string other = write(dir, "other.obj", falling(-10, false, true));
  const struct {
    std::string args;
    std::string expect;
  } cases[] = {
      {f0 + " " + more, "more.obj"},
      {f0 + " " + other, "other.obj"},
      {f0, "give two frames"},
      {f0 + " " + f0 + " " + f0, "give two frames"},
      {f0 + " " + f0 + " --method naive", "expected kdop, hash or sap"},
      {f0 + " " + f0 + " --method kdop:leaf=0", "leaf"},
      {f0 + " " + f0 + " --min-separation 1 --min-separation-rel 1", "excludes"},
      {f0 + " " + f0 + " --queries " + f0, "not both"},
      {f0 + " " + (dir / "missing.obj").string(), "missing.obj"},
      {f0 + " " + f0 + " --impacts " + dir.path().string(), "--impacts"},
      {f0 + " " + f0 + " --min-separation 1e308", "must be in [0, 2^1000], got 1e+308"},
      {f0 + " " + f0 + " --min-separation-rel 1e305", "must be in [0, 2^1000]"},
      {"--queries " + write(dir, "q.txt", kQueries) + " --min-separation 1e308", "must be in [0, 2^1000]"},
  };
  for (const auto& c : cases) {
    const auto r = run_cli("ccd " + c.args);
    EXPECT_NE(r.status, 0) << c.args << "\n" << r.out;
    EXPECT_NE(r.out.find(c.expect), std::string::npos) << c.args << "\n" << r.out;
  }
}

}  // namespace
}  // namespace crumple
