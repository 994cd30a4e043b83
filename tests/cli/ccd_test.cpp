// `crumple ccd --queries FILE`: answers per line, exact hex input, δ, and clear errors.
#include <gtest/gtest.h>

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

}  // namespace
}  // namespace crumple
