// `crumple simulate`: outputs, resume bit for bit, interrupts, files as input, errors.
#include <crumple/io/mesh_io.hpp>
#include <crumple/io/x3d.hpp>
#include <crumple/mesh/shapes.hpp>
#include <support/run_cli.hpp>
#include <support/temp_dir.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <csignal>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <sstream>
#include <string>
#include <vector>

namespace crumple {
namespace {

using testing::read_lines;
using testing::run_cli;


std::size_t count_fields(const std::string& line) { return static_cast<std::size_t>(std::count(line.begin(), line.end(), ',')) + 1; }

/// The field `column` (0-based) of a stats.csv line.
std::string field(const std::string& line, std::size_t column) {
  std::stringstream in(line);
  std::string item;
  for (std::size_t k = 0; k <= column && std::getline(in, item, ','); ++k) {
  }
  return item;
}

TEST(Simulate, WritesFramesStatsAndState) {
  const testing::TempDir dir;
  const auto r = run_cli("simulate hanging-cloth:nx=4,ny=4 --frames 5 -o " + dir.path().string());
  ASSERT_EQ(r.status, 0) << r.out;
  EXPECT_NE(r.out.find("collision share"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find(" 5 (6 written to "), std::string::npos) << r.out;
  for (int f = 0; f <= 5; ++f) {
    EXPECT_TRUE(std::filesystem::exists(dir / "frames" / ("00000" + std::to_string(f) + ".obj"))) << f;
  }
  const auto lines = read_lines(dir / "stats.csv");
  ASSERT_EQ(lines.size(), 7u);
  EXPECT_EQ(lines[0].rfind("frame,time,integrate_ms,detect_ms,response_ms,vf,ee,tt,collision_share", 0), 0u)
      << lines[0];
  for (const auto& line : lines) EXPECT_EQ(count_fields(line), count_fields(lines[0])) << line;
  EXPECT_EQ(lines[6].rfind("5,", 0), 0u);
  const io::MassSpringData state = io::read_mass_spring(dir / "state.x3d");
  EXPECT_EQ(state.positions.size(), 25u);
  EXPECT_EQ(state.masses[0], 0) << "the pinned corner";
  EXPECT_EQ(state.faces.size(), 32u);
  const TriMesh last = io::read_mesh(dir / "frames" / "000005.obj");
  EXPECT_EQ(last.positions(), state.positions) << "the last frame is the saved state";
  EXPECT_TRUE(std::filesystem::exists(dir / "state.json"));
  // The last columns: the fail-safe's zone vertices (no response here: 0) and the longest
  // spring over its rest length, here that of the saved state.
  const std::string tail = ",ccd_zone_vertices,longest_spring";
  ASSERT_GT(lines[0].size(), tail.size());
  EXPECT_EQ(lines[0].substr(lines[0].size() - tail.size()), tail) << lines[0];
  Scalar longest = 0;
  for (std::size_t s = 0; s < state.springs.size(); ++s) {
    const Vec3 d = state.positions[static_cast<std::size_t>(state.springs[s][0])] -
                   state.positions[static_cast<std::size_t>(state.springs[s][1])];
    longest = std::max(longest, d.norm() / state.rest_length[s]);
  }
  EXPECT_GT(longest, 1) << "the hanging cloth stretches";
  const std::size_t columns = count_fields(lines[0]);
  EXPECT_EQ(field(lines[6], columns - 2), "0") << lines[6];
  EXPECT_NEAR(std::stod(field(lines[6], columns - 1)), longest, 1e-8 * longest) << lines[6];
}

/// Simulating N + M frames equals simulating N, then resuming from the saved state for M.
void expect_resume_bit_for_bit(const std::string& scene, int n, int m, const std::string& extra) {
  const testing::TempDir dir;
  const auto whole = dir / "whole", first = dir / "first", second = dir / "second";
  auto r = run_cli("simulate " + scene + " --frames " + std::to_string(n + m) + " -q " + extra + " -o " + whole.string());
  ASSERT_EQ(r.status, 0) << r.out;
  r = run_cli("simulate " + scene + " --frames " + std::to_string(n) + " -q " + extra + " -o " + first.string());
  ASSERT_EQ(r.status, 0) << r.out;
  r = run_cli("simulate " + (first / "state.x3d").string() + " --frames " + std::to_string(m) + " -q -o " +
              second.string());
  ASSERT_EQ(r.status, 0) << r.out;
  const io::MassSpringData a = io::read_mass_spring(whole / "state.x3d");
  const io::MassSpringData b = io::read_mass_spring(second / "state.x3d");
  EXPECT_EQ(a.positions, b.positions) << scene;
  EXPECT_EQ(a.velocities, b.velocities) << scene;
  char name[32];
  std::snprintf(name, sizeof name, "%06d.obj", n + m);
  EXPECT_TRUE(std::filesystem::exists(second / "frames" / name)) << "frame numbers continue";
  const auto sa = read_lines(whole / "stats.csv"), sb = read_lines(second / "stats.csv");
  ASSERT_EQ(sb.size(), static_cast<std::size_t>(m + 2));
  // Same frame number, time and contact counts on the last line.
  const auto prefix = [](const std::string& line) { return line.substr(0, line.find(',', line.find(',') + 1)); };
  EXPECT_EQ(prefix(sa.back()), prefix(sb.back()));
}

TEST(Simulate, ResumesHangingClothBitForBit) { expect_resume_bit_for_bit("hanging-cloth:nx=5,ny=5", 6, 5, ""); }

// A run's state.x3d whose state.json is gone cannot resume: the run says it starts over as a
// plain MassSpring file instead of doing so silently.
TEST(Simulate, StateWithoutItsSideFileIsSaidNotToResume) {
  const testing::TempDir dir;
  auto r = run_cli("simulate hanging-cloth:nx=4,ny=4 --frames 2 -q -o " + (dir / "run").string());
  ASSERT_EQ(r.status, 0) << r.out;
  r = run_cli("simulate " + (dir / "run" / "state.x3d").string() + " --frames 1 -q -o " + (dir / "again").string());
  ASSERT_EQ(r.status, 0) << r.out;
  EXPECT_EQ(r.out.find("no crumple state file"), std::string::npos) << "a state with its side file resumes: " << r.out;
  std::filesystem::remove(dir / "run" / "state.json");
  r = run_cli("simulate " + (dir / "run" / "state.x3d").string() + " --frames 1 -q -o " + (dir / "over").string());
  ASSERT_EQ(r.status, 0) << r.out;
  EXPECT_NE(r.out.find("warning: no crumple state file"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("not resuming"), std::string::npos) << r.out;
}

TEST(Simulate, ResumesWithObstaclesResponseAndKinematicsBitForBit) {
  expect_resume_bit_for_bit("cloth-on-sphere:n=5,sphere-speed=0.2", 4, 3, "--dt 0.004 --substeps 4");
  expect_resume_bit_for_bit("twisted-ribbon:nx=8,ny=1", 3, 3, "--integrator symplectic-euler --dt 0.0005");
}

TEST(Simulate, ResumesTheStochasticDetectorsStateBitForBit) {
  // Response on: contacts found by the stochastic detector move the cloth, so a resumed run
  // matches only if the detector's kept pairs and generator are restored.
  expect_resume_bit_for_bit("hanging-cloth:nx=6,ny=6", 30, 10,
                            "--response on --method stochastic:variant=vertex,active=15");
  // Response off: positions never depend on contacts; the contact counts of every resumed
  // frame (stats.csv columns vf, ee) must still be the uninterrupted run's.
  const testing::TempDir dir;
  const std::string opts = " -q --method stochastic:variant=direct,active=10,propagation=none";
  auto r = run_cli("simulate hanging-cloth:nx=6,ny=6 --frames 60" + opts + " -o " + (dir / "whole").string());
  ASSERT_EQ(r.status, 0) << r.out;
  r = run_cli("simulate hanging-cloth:nx=6,ny=6 --frames 40" + opts + " -o " + (dir / "first").string());
  ASSERT_EQ(r.status, 0) << r.out;
  r = run_cli("simulate " + (dir / "first" / "state.x3d").string() + " --frames 20 -q -o " + (dir / "second").string());
  ASSERT_EQ(r.status, 0) << r.out;
  const auto counts = [](const std::string& line) {  // frame, vf, ee
    std::vector<std::string> f;
    std::stringstream ss(line);
    for (std::string x; std::getline(ss, x, ',');) f.push_back(x);
    return std::vector<std::string>{f.at(0), f.at(5), f.at(6)};
  };
  const auto whole = read_lines(dir / "whole" / "stats.csv"), second = read_lines(dir / "second" / "stats.csv");
  ASSERT_EQ(second.size(), 22u);
  std::size_t with_contacts = 0;
  for (std::size_t i = 1; i < second.size(); ++i) {
    EXPECT_EQ(counts(second[i]), counts(whole[40 + i])) << "line " << i;
    with_contacts += counts(second[i])[1] != "0" || counts(second[i])[2] != "0";
  }
  EXPECT_GT(with_contacts, 5u) << "the frames compared must have contacts";
}

TEST(Simulate, InterruptLeavesCompleteFiles) {
  const testing::TempDir dir;
  EXPECT_EQ(testing::interrupt_simulation(dir.path(), SIGINT, {"--every", "7"}), 130);
  const auto lines = read_lines(dir / "stats.csv");
  ASSERT_GE(lines.size(), 10u);
  for (const auto& line : lines) EXPECT_EQ(count_fields(line), count_fields(lines[0])) << line;
  const io::MassSpringData state = io::read_mass_spring(dir / "state.x3d");
  EXPECT_EQ(state.positions.size(), 49u);
  for (const auto& entry : std::filesystem::directory_iterator(dir / "frames")) {
    EXPECT_EQ(entry.path().extension(), ".obj") << "no temporary file left behind";
    EXPECT_NO_THROW(io::read_mesh(entry.path())) << entry.path();
  }
}

TEST(Simulate, MeshFileWithPinsAndFormats) {
  const testing::TempDir dir;
  const TriMesh mesh = shapes::lattice(3, 3);
  io::write_obj(dir / "cloth.obj", mesh.positions(), mesh.topology().faces());
  auto r = run_cli("simulate " + (dir / "cloth.obj").string() + " -p 'pins=0;3' -p stiffness=200 --frames 4 " +
                   "--format ply -o " + (dir / "out").string());
  ASSERT_EQ(r.status, 0) << r.out;
  const TriMesh last = io::read_mesh(dir / "out" / "frames" / "000004.ply");
  EXPECT_EQ(last.positions()[0], mesh.positions()[0]);
  EXPECT_EQ(last.positions()[3], mesh.positions()[3]);
  EXPECT_NE(last.positions()[15], mesh.positions()[15]);
  // The saved state is a MassSpring X3D that resumes without a scene.
  r = run_cli("simulate " + (dir / "out" / "state.x3d").string() + " --frames 2 -q -o " + (dir / "again").string());
  ASSERT_EQ(r.status, 0) << r.out;
  EXPECT_TRUE(std::filesystem::exists(dir / "again" / "frames" / "000006.obj"));
}

TEST(Simulate, BadInputIsAOneLineError) {
  auto r = run_cli("simulate bogus-scene");
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.out.find("valid: hanging-cloth"), std::string::npos) << r.out;
  r = run_cli("simulate hanging-cloth:zz=1");
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.out.find("unknown key 'zz'"), std::string::npos) << r.out;
  r = run_cli("simulate hanging-cloth --integrator leapfrog --frames 1");
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.out.find("implicit-euler"), std::string::npos) << r.out;
  r = run_cli("simulate hanging-cloth --response maybe --frames 1");
  EXPECT_NE(r.status, 0);
  r = run_cli("simulate /no/such/file.obj");
  EXPECT_NE(r.status, 0);
  r = run_cli("simulate --help");
  EXPECT_EQ(r.status, 0);
  EXPECT_NE(r.out.find("cloth-on-sphere"), std::string::npos);
  EXPECT_NE(r.out.find("twisted-ribbon"), std::string::npos);
}

TEST(Simulate, FailSafeFlagIsSavedAndChecked) {
  const testing::TempDir dir;
  auto r = run_cli("simulate cloth-on-sphere:n=4 --frames 2 -q --fail-safe off -o " + (dir / "off").string());
  ASSERT_EQ(r.status, 0) << r.out;
  std::ifstream in(dir / "off" / "state.json");
  const std::string json((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_NE(json.find("\"fail_safe\":false"), std::string::npos) << json;
  const auto lines = read_lines(dir / "off" / "stats.csv");
  ASSERT_FALSE(lines.empty());
  EXPECT_NE(lines[0].find(",ccd_ms,ccd_impacts,ccd_frozen"), std::string::npos) << lines[0];
  r = run_cli("simulate cloth-on-sphere:n=4 --frames 1 -q --fail-safe maybe -o " + (dir / "bad").string());
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.out.find("--fail-safe expects on or off, got 'maybe'"), std::string::npos) << r.out;
}

// The motion settings: the scene's by default (crumple retries twice), overridden by the options,
// saved in state.json and kept by a resumed run; a bad value is refused with the option's name.
TEST(Simulate, MotionSettingsAreSavedAndKept) {
  const testing::TempDir dir;
  const auto state_json = [&](const char* run) {
    std::ifstream in(dir / run / "state.json");
    return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  };
  auto r = run_cli("simulate crumple:n=4 --frames 1 -q -o " + (dir / "scene").string());
  ASSERT_EQ(r.status, 0) << r.out;
  EXPECT_NE(state_json("scene").find("\"motion_retries\":2"), std::string::npos) << state_json("scene");
  EXPECT_NE(state_json("scene").find("\"motion_search\":false"), std::string::npos);
  EXPECT_NE(state_json("scene").find("\"push_relaxation\":0.5"), std::string::npos) << state_json("scene");
  r = run_cli("simulate crumple:n=4 --frames 1 -q --motion-retries 0 --motion-search on --push-relaxation 0.25 -o " +
              (dir / "set").string());
  ASSERT_EQ(r.status, 0) << r.out;
  EXPECT_NE(state_json("set").find("\"motion_retries\":0"), std::string::npos) << state_json("set");
  EXPECT_NE(state_json("set").find("\"motion_search\":true"), std::string::npos);
  EXPECT_NE(state_json("set").find("\"push_relaxation\":0.25"), std::string::npos) << state_json("set");
  r = run_cli("simulate " + (dir / "set" / "state.x3d").string() + " --frames 1 -q");
  ASSERT_EQ(r.status, 0) << r.out;
  EXPECT_NE(state_json("set").find("\"motion_retries\":0"), std::string::npos) << "kept on resume";
  EXPECT_NE(state_json("set").find("\"motion_search\":true"), std::string::npos) << "kept on resume";
  EXPECT_NE(state_json("set").find("\"push_relaxation\":0.25"), std::string::npos) << "kept on resume";
  r = run_cli("simulate crumple:n=4 --frames 1 -q --motion-search maybe -o " + (dir / "bad").string());
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.out.find("--motion-search expects on or off, got 'maybe'"), std::string::npos) << r.out;
  r = run_cli("simulate crumple:n=4 --frames 1 -q --motion-retries -1 -o " + (dir / "bad").string());
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.out.find("--motion-retries"), std::string::npos) << r.out;
  for (const char* bad : {"0", "1.5", "nan"}) {
    r = run_cli(std::string("simulate crumple:n=4 --frames 1 -q --push-relaxation ") + bad + " -o " +
                (dir / "bad").string());
    EXPECT_NE(r.status, 0) << bad;
    EXPECT_NE(r.out.find("--push-relaxation"), std::string::npos) << r.out;
  }
  r = run_cli("simulate crumple:n=4 --frames 1 -q --push-relaxation=-1e-9 -o " + (dir / "bad").string());
  EXPECT_NE(r.out.find("got -1e-09"), std::string::npos) << r.out;
  // A saved value out of range is refused with the file's name.
  std::string json = state_json("set");
  const auto at = json.find("\"push_relaxation\":0.25");
  ASSERT_NE(at, std::string::npos);
  json.replace(at, std::string("\"push_relaxation\":0.25").size(), "\"push_relaxation\":2");
  std::ofstream(dir / "set" / "state.json") << json;
  r = run_cli("simulate " + (dir / "set" / "state.x3d").string() + " --frames 1 -q");
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.out.find("state.json"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("key 'push_relaxation' expects a number in (0, 1], got '2'"), std::string::npos) << r.out;
}

// --response-from: the 8x8 hanging cloth falls through itself for 200 frames, then untangles;
// the column intersecting_pairs counts the pairs (-1 while not measured) down to 0, the column
// pinches the pairs sharing a vertex (likewise), and the run says when both reach 0. With
// --untangle off nothing is measured or printed.
TEST(Simulate, ResponseFromUntanglesAndCountsIntersectingPairs) {
  const testing::TempDir dir;
  auto r = run_cli("simulate hanging-cloth:nx=8,ny=8 --response-from 200 --frames 240 --every 100 -o " +
                   (dir / "on").string());
  ASSERT_EQ(r.status, 0) << r.out;
  EXPECT_NE(r.out.find("response off until frame 200, then on"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("0 intersecting triangle pairs at frame"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find(" 240 (3 written to "), std::string::npos) << "--every 100: frames 0, 100, 200\n" << r.out;
  EXPECT_EQ(std::distance(std::filesystem::directory_iterator(dir / "on" / "frames"), {}), 3);
  auto lines = read_lines(dir / "on" / "stats.csv");
  ASSERT_EQ(lines.size(), 242u);
  const std::size_t at = lines[0].find(",intersecting_pairs,contours,untangle_pulls,pinches,");
  ASSERT_NE(at, std::string::npos) << lines[0];
  const auto column =  // intersecting_pairs': the commas before it
      static_cast<std::size_t>(std::count(lines[0].begin(), lines[0].begin() + static_cast<std::ptrdiff_t>(at) + 1, ','));
  const std::size_t pinches = column + 3;
  EXPECT_EQ(field(lines[200], column), "-1") << "frame 199: no response, not measured";
  EXPECT_EQ(field(lines[201], column), "-1") << "frame 200: the last without response";
  EXPECT_EQ(field(lines[201], pinches), "-1") << "frame 200: not measured";
  EXPECT_GE(std::stoi(field(lines[202], pinches)), 0) << "frame 201: measured";
  EXPECT_GT(std::stoi(field(lines[202], column)), 0) << "frame 201: still tangled";
  EXPECT_GT(std::stoi(field(lines[202], column + 2)), 0) << "pushes";
  EXPECT_EQ(field(lines[241], column), "0") << "frame 240: untangled";
  EXPECT_EQ(field(lines[241], pinches), "0") << "frame 240: no pinch either";
  std::ifstream in(dir / "on" / "state.json");
  const std::string json((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_NE(json.find("\"untangle\":true"), std::string::npos) << json;

  r = run_cli("simulate hanging-cloth:nx=8,ny=8 --response-from 200 --frames 210 --untangle off --every 100 -o " +
              (dir / "off").string());
  ASSERT_EQ(r.status, 0) << r.out;
  EXPECT_EQ(r.out.find("0 intersecting triangle pairs at frame"), std::string::npos) << r.out;
  lines = read_lines(dir / "off" / "stats.csv");
  ASSERT_EQ(lines.size(), 212u);
  for (std::size_t k = 1; k < lines.size(); ++k) {
    EXPECT_EQ(field(lines[k], column), "-1") << lines[k];
    EXPECT_EQ(field(lines[k], pinches), "-1") << lines[k];
  }

  // A run that ends before the switch saves its state with the response off.
  r = run_cli("simulate hanging-cloth:nx=4,ny=4 --response-from 10 --frames 5 -q -o " + (dir / "early").string());
  ASSERT_EQ(r.status, 0) << r.out;
  std::ifstream early(dir / "early" / "state.json");
  const std::string early_json((std::istreambuf_iterator<char>(early)), std::istreambuf_iterator<char>());
  EXPECT_NE(early_json.find("\"response\":false"), std::string::npos) << early_json;
  EXPECT_NE(json.find("\"response\":true"), std::string::npos) << json;

  r = run_cli("simulate hanging-cloth:nx=4,ny=4 --response-from 3 --response off --frames 5 -q -o " +
              (dir / "bad").string());
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.out.find("--response-from needs the response on"), std::string::npos) << r.out;
  r = run_cli("simulate hanging-cloth:nx=4,ny=4 --untangle maybe --frames 1 -q -o " + (dir / "bad2").string());
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.out.find("--untangle expects on or off, got 'maybe'"), std::string::npos) << r.out;
}

}  // namespace
}  // namespace crumple
