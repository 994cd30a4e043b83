// Issue 45: the tool does no harm to the user's files, never fails silently and keeps its
// resources bounded by the input (divergence, outputs, signals, typos).
#include <crumple/io/mesh_io.hpp>
#include <crumple/io/x3d.hpp>
#include <crumple/mesh/shapes.hpp>
#include <support/run_cli.hpp>
#include <support/temp_dir.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

namespace crumple {
namespace {

using testing::read_lines;
using testing::run_cli;


std::vector<std::string> fields(const std::string& line) {
  std::vector<std::string> out;
  std::stringstream in(line);
  for (std::string f; std::getline(in, f, ',');) out.push_back(f);
  return out;
}

std::string quoted(const std::filesystem::path& p) { return "'" + p.string() + "'"; }

/// `crumple ARGS` run from the folder `cwd`.
testing::CliResult run_in(const std::filesystem::path& cwd, const std::string& args) {
  return testing::run_program("cd " + quoted(cwd) + " && " + CRUMPLE_CLI, args);
}

std::size_t count_files(const std::filesystem::path& dir) {
  if (!std::filesystem::is_directory(dir)) return 0;
  return static_cast<std::size_t>(std::distance(std::filesystem::directory_iterator(dir),
                                                std::filesystem::directory_iterator()));
}

// Defect 4: the repro exited 0 with coordinates ~1e137 and NaN frames shown as 0
// contacts. It must stop at the first bad step, name the frame and the remedy, keep only
// finite frames and save the last good state, which resumes with a stable integrator.
TEST(Safety, DivergingSimulationStopsWithTheLastGoodState) {
  const testing::TempDir dir;
  const auto out = dir / "run";
  auto r = run_cli("simulate cloth-on-sphere -i explicit-euler --dt 0.01 --substeps 1 -n 100 -o " +
                   out.string());
  EXPECT_EQ(r.status, 1) << r.out;
  EXPECT_NE(r.out.find("warning: the time step 0.01 s is beyond explicit-euler's stable range"),
            std::string::npos)
      << r.out;
  EXPECT_NE(r.out.find("diverged at frame"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("--dt"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("implicit-euler"), std::string::npos) << r.out;
  const auto lines = read_lines(out / "stats.csv");
  ASSERT_GE(lines.size(), 2u);
  ASSERT_LT(lines.size(), 102u) << "stopped before the end";
  const auto header = fields(lines[0]);
  for (const char* column : {"energy", "max_speed", "min_x", "max_z"}) {
    EXPECT_NE(std::find(header.begin(), header.end(), column), header.end()) << column;
  }
  for (std::size_t i = 1; i < lines.size(); ++i) {
    const auto f = fields(lines[i]);
    ASSERT_EQ(f.size(), header.size()) << lines[i];
    for (std::size_t c = 13; c < f.size(); ++c) {
      EXPECT_TRUE(std::isfinite(std::stod(f[c]))) << lines[i];
      EXPECT_LT(std::abs(std::stod(f[c])), 1e6) << lines[i];
    }
  }
  const io::MassSpringData state = io::read_mass_spring(out / "state.x3d");
  for (const Vec3& x : state.positions) ASSERT_TRUE(x.allFinite() && x.norm() < 100);
  const std::string last_frame = fields(lines.back())[0];
  EXPECT_NE(r.out.find("last good state (frame " + last_frame + ")"), std::string::npos) << r.out;
  // Resumed in place with a stable integrator: the run goes on, nothing is lost.
  r = run_cli("simulate " + (out / "state.x3d").string() + " -i implicit-euler -n 3 -q");
  ASSERT_EQ(r.status, 0) << r.out;
  const auto after = read_lines(out / "stats.csv");
  ASSERT_EQ(after.size(), lines.size() + 3);
  EXPECT_EQ(fields(after.back())[0], std::to_string(std::stoi(last_frame) + 3));
}

// Defect 4: the built-in scenes' own time step is split into stable substeps for an explicit
// integrator (the run no longer diverges), and the choice is said.
TEST(Safety, SceneTimeStepIsSplitForAnExplicitIntegrator) {
  const testing::TempDir dir;
  const auto r = run_cli("simulate cloth-on-sphere:n=6 -i symplectic-euler -n 20 -o " +
                         dir.path().string());
  ASSERT_EQ(r.status, 0) << r.out;
  EXPECT_NE(r.out.find("beyond symplectic-euler's stable range"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("substeps of"), std::string::npos) << r.out;
}

// Defect 5: resuming DIR/state.x3d without --out truncated DIR's stats.csv (or wrote a second
// run elsewhere); it continues the run in DIR and appends.
TEST(Safety, ResumeWithoutOutAppendsToTheRunsStats) {
  const testing::TempDir dir;
  const auto out = dir / "run";
  ASSERT_EQ(run_cli("simulate hanging-cloth:nx=4,ny=4 -n 5 -q -o " + out.string()).status, 0);
  ASSERT_EQ(read_lines(out / "stats.csv").size(), 7u);
  const auto r = run_in(dir.path(), "simulate run/state.x3d -n 3 -q");
  ASSERT_EQ(r.status, 0) << r.out;
  const auto lines = read_lines(out / "stats.csv");
  ASSERT_EQ(lines.size(), 10u);
  for (std::size_t i = 1; i < lines.size(); ++i) EXPECT_EQ(fields(lines[i])[0], std::to_string(i - 1));
  EXPECT_TRUE(std::filesystem::exists(out / "frames" / "000008.obj"));
  EXPECT_FALSE(std::filesystem::exists(dir / "crumple-out")) << "no second run elsewhere";
}

// Defect 5: a folder holding another run is refused (stale frames would mix), unless --force,
// which replaces that run's files only.
TEST(Safety, OutputFolderOfAnotherRunNeedsForce) {
  const testing::TempDir dir;
  const auto out = dir / "run";
  ASSERT_EQ(run_cli("simulate hanging-cloth:nx=4,ny=4 -n 6 -q -o " + out.string()).status, 0);
  std::ofstream(out / "notes.txt") << "mine";
  auto r = run_cli("simulate hanging-cloth:nx=4,ny=4 -n 2 -q -o " + out.string());
  EXPECT_EQ(r.status, 1) << r.out;
  EXPECT_NE(r.out.find("holds another run"), std::string::npos) << r.out;
  EXPECT_EQ(read_lines(out / "stats.csv").size(), 8u) << "untouched";
  r = run_cli("simulate hanging-cloth:nx=4,ny=4 -n 2 -q --force -o " + out.string());
  ASSERT_EQ(r.status, 0) << r.out;
  EXPECT_EQ(read_lines(out / "stats.csv").size(), 4u);
  EXPECT_EQ(count_files(out / "frames"), 3u) << "no stale frame of the first run";
  EXPECT_TRUE(std::filesystem::exists(out / "notes.txt")) << "only the run's own files go";
}

// Defect 5: a --video folder holding another video's pictures would mix them into this one.
TEST(Safety, VideoFolderOfAnotherVideoNeedsForce) {
  const testing::TempDir dir;
  const auto video = dir / "video";
  const std::string base = "render hanging-cloth:nx=4,ny=4 --size 40x30 -q --video " + video.string();
  ASSERT_EQ(run_cli(base + " --frame 3").status, 0);
  ASSERT_TRUE(std::filesystem::exists(video / "000003.png"));
  std::ofstream(video / "notes.txt") << "mine";
  auto r = run_cli(base + " --frame 1");
  EXPECT_EQ(r.status, 1) << r.out;
  EXPECT_NE(r.out.find("holds the pictures of another video"), std::string::npos) << r.out;
  EXPECT_TRUE(std::filesystem::exists(video / "000003.png")) << "untouched";
  r = run_cli(base + " --frame 1 --force");
  ASSERT_EQ(r.status, 0) << r.out;
  EXPECT_FALSE(std::filesystem::exists(video / "000003.png")) << "no stale picture";
  EXPECT_TRUE(std::filesystem::exists(video / "000001.png"));
  EXPECT_TRUE(std::filesystem::exists(video / "notes.txt")) << "only the video's own files go";
}

// Defect 5: outputs are checked before any work; file system errors are user errors (exit 1)
// with the OS's reason, never `internal error`.
TEST(Safety, BadOutputPathsFailFirstAsUserErrors) {
  const testing::TempDir dir;
  std::ofstream(dir / "file") << "x";
  const std::vector<std::pair<std::string, std::string>> cases{
      {"simulate hanging-cloth:nx=4,ny=4 -n 2 -o " + (dir / "file").string(), "not a folder"},
      {"simulate hanging-cloth:nx=4,ny=4 -n 2 -o " + (dir / "file" / "sub").string(), "Not a directory"},
      {"render hanging-cloth --out " + (dir / "file" / "x.png").string(), "not a folder"},
      {"render hanging-cloth --video " + (dir / "file").string(), "not a folder"},
      {"detect --contacts " + dir.path().string(), "is a folder"},
      {"bench --quick --sections budget -q --out " + (dir / "file").string(), "not a folder"},
  };
  for (const auto& [args, needle] : cases) {
    const auto r = run_cli(args);
    EXPECT_EQ(r.status, 1) << args << "\n" << r.out;
    EXPECT_NE(r.out.find("crumple: error:"), std::string::npos) << args << "\n" << r.out;
    EXPECT_EQ(r.out.find("internal error"), std::string::npos) << args << "\n" << r.out;
    EXPECT_NE(r.out.find(needle), std::string::npos) << args << "\n" << r.out;
  }
}

// Defect 5: x/t.ply and y/t.ply wrote one t.tsv (the second frame's contacts over the first's).
TEST(Safety, ContactFilesOfTwoFramesNeverShareAName) {
  const testing::TempDir dir;
  const TriMesh mesh = shapes::folded_cloth();
  for (const char* sub : {"x", "y"}) {
    std::filesystem::create_directories(dir / sub);
    io::write_ply(dir / sub / "t.ply", mesh.positions(), mesh.topology().faces());
  }
  const auto r = run_cli("detect " + (dir / "x" / "t.ply").string() + " " +
                         (dir / "y" / "t.ply").string() + " -t 0.02 --contacts " +
                         (dir / "contacts").string());
  EXPECT_EQ(r.status, 1) << r.out;
  EXPECT_NE(r.out.find("would both write t.tsv"), std::string::npos) << r.out;
  EXPECT_EQ(count_files(dir / "contacts"), 0u);
}

// Defect 5: SIGTERM (a scheduler's stop) is handled like Ctrl-C: complete files, a state that
// resumes.
TEST(Safety, SigtermLeavesCompleteFilesAndAResumableState) {
  const testing::TempDir dir;
  EXPECT_EQ(testing::interrupt_simulation(dir.path(), SIGTERM), 128 + SIGTERM);
  const auto lines = read_lines(dir / "stats.csv");
  ASSERT_GE(lines.size(), 10u);
  for (const auto& line : lines) EXPECT_EQ(fields(line).size(), fields(lines[0]).size()) << line;
  const auto r = run_cli("simulate " + (dir / "state.x3d").string() + " -n 2 -q");
  ASSERT_EQ(r.status, 0) << r.out;
  EXPECT_EQ(read_lines(dir / "stats.csv").size(), lines.size() + 2);
}

// Defect 2 (CLI): output that never reaches its file is an error, for every subcommand.
TEST(Safety, FullStandardOutputIsAnError) {
  const testing::TempDir dir;
  const TriMesh mesh = shapes::folded_cloth();
  io::write_obj(dir / "m.obj", mesh.positions(), mesh.topology().faces());
  for (const std::string& args : {"info " + (dir / "m.obj").string(),
                                 "detect " + (dir / "m.obj").string(), std::string("--help"),
                                 std::string("detect --help")}) {
    // stdout to the full device, stderr (the message) to the test.
    const auto r = testing::run_program("{ " + std::string(CRUMPLE_CLI), args + " >/dev/full; }");
    EXPECT_EQ(r.status, 1) << args << "\n" << r.out;
    EXPECT_NE(r.out.find("crumple: error: cannot write the standard output"), std::string::npos)
        << args << "\n" << r.out;
  }
}

// Defect 5: `bench --quick` from the repository root overwrote the committed report: its
// default output is a folder of its own, and --quick never replaces a full report.
TEST(Safety, QuickBenchNeverOverwritesAFullReport) {
  const testing::TempDir dir;
  auto r = run_in(dir.path(), "bench --quick --sections budget -q");
  ASSERT_EQ(r.status, 0) << r.out;
  EXPECT_TRUE(std::filesystem::exists(dir / "crumple-bench" / "bench.md")) << r.out;
  const auto full = dir / "report";
  std::filesystem::create_directories(full);
  std::ofstream(full / "bench.json") << "{\"machine\":\"m\",\"quick\":false}\n";
  std::ofstream(full / "bench.md") << "full report\n";
  r = run_cli("bench --quick --sections budget -q --out " + full.string());
  EXPECT_EQ(r.status, 1) << r.out;
  EXPECT_NE(r.out.find("holds a full report"), std::string::npos) << r.out;
  EXPECT_EQ(read_lines(full / "bench.md"), std::vector<std::string>{"full report"});
}

// Defect 6: a thickness as large as the mesh made every pair a contact (4.2 GB, bad_alloc).
// The estimate stops it before any detection; a large thickness is flagged.
TEST(Safety, HugeThicknessStopsBeforeDetecting) {
  const testing::TempDir dir;
  const TriMesh mesh = shapes::lattice(20, 20);
  io::write_obj(dir / "sheet.obj", mesh.positions(), mesh.topology().faces());
  auto r = run_cli("detect " + (dir / "sheet.obj").string() + " -t 100 --max-contacts 10000");
  EXPECT_EQ(r.status, 1) << r.out;
  EXPECT_NE(r.out.find("warning: the thickness 100 is"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("contacts on this mesh"), std::string::npos) << r.out;
  EXPECT_EQ(r.out.find("frame 0"), std::string::npos) << "nothing detected";
  // Below the limit it runs, and the default thickness draws no warning.
  r = run_cli("detect " + (dir / "sheet.obj").string() + " -t 100 --max-contacts 0 -k vf");
  EXPECT_EQ(r.status, 0) << r.out;
  r = run_cli("detect " + (dir / "sheet.obj").string());
  EXPECT_EQ(r.status, 0) << r.out;
  EXPECT_EQ(r.out.find("warning"), std::string::npos) << r.out;
}

// Defect 6: the contact estimate squared unscaled distances: at coordinates near 1e200 every
// pair whose boxes met counted (h^2 = inf), near 1e-200 too (everything squared to 0), so the
// same sheet gave another estimate, and another verdict, at another scale. It is the same.
TEST(Safety, ContactEstimateIsTheSameAtEveryScale) {
  const testing::TempDir dir;
  const TriMesh mesh = shapes::folded_cloth();
  std::string first;
  for (const Scalar scale : {1.0, 1e200, 1e-200}) {
    Positions x = mesh.positions();
    for (Vec3& p : x) p *= scale;
    const auto file = dir / "sheet.obj";
    io::write_obj(file, x, mesh.topology().faces());
    char thickness[32];
    std::snprintf(thickness, sizeof thickness, "%.17g", 0.23 * scale);
    const auto r = run_cli("detect " + file.string() + " -t " + thickness + " --max-contacts 10");
    EXPECT_EQ(r.status, 1) << scale << "\n" << r.out;
    const std::size_t at = r.out.find("would give about ");
    ASSERT_NE(at, std::string::npos) << scale << "\n" << r.out;
    const std::string estimate = r.out.substr(at, r.out.find(" contacts", at) - at);
    if (first.empty()) first = estimate;
    EXPECT_EQ(estimate, first) << "at scale " << scale << "\n" << r.out;
    EXPECT_EQ(r.out.find("inf"), std::string::npos) << scale << "\n" << r.out;
  }
}

// Defect 6: typos in sizes end in a clear bound, not `internal error` or a 309-digit number.
TEST(Safety, OutOfRangeSizesAreClearErrors) {
  const std::vector<std::pair<std::string, std::string>> cases{
      {"detect --threads 100000", "--threads must be between 0 (all cores) and 1024"},
      {"detect --threads -1", "--threads must be between"},
      {"compare --size 100000", "--size must be between 2 and 1000"},
      {"compare --frames 0", "--frames must be between 1 and"},
      {"simulate hanging-cloth -n 1 --threads 100000", "--threads must be between"},
      {"simulate hanging-cloth:nx=100000,ny=100000 -n 1", "more than 4000000"},
      {"simulate hanging-cloth:nx=100000000 -n 1", "'nx' must be between 1 and 100000"},
      {"render hanging-cloth --size 8192x8192 --aa 4 --out x.png", "lower --aa or --size"},
  };
  const auto has_long_number = [](const std::string& text) {
    std::size_t run = 0;
    for (const char c : text) {
      run = std::isdigit(static_cast<unsigned char>(c)) ? run + 1 : 0;
      if (run >= 12) return true;
    }
    return false;
  };
  for (const auto& [args, needle] : cases) {
    const auto r = run_cli(args);
    EXPECT_EQ(r.status, 1) << args << "\n" << r.out;
    EXPECT_NE(r.out.find(needle), std::string::npos) << args << "\n" << r.out;
    EXPECT_FALSE(has_long_number(r.out)) << args << "\n" << r.out;
  }
}

// Defaults: the fast exact detector everywhere; naive stays the reference of compare.
TEST(Safety, DefaultMethodIsKdop) {
  const testing::TempDir dir;
  auto r = run_cli("detect");
  ASSERT_EQ(r.status, 0) << r.out;
  EXPECT_EQ(r.out.rfind("method kdop,", 0), 0u) << r.out;
  r = run_cli("compare --size 6 --frames 2");
  ASSERT_EQ(r.status, 0) << r.out;
  EXPECT_EQ(r.out.rfind("method kdop against naive", 0), 0u) << r.out;
  r = run_cli("simulate hanging-cloth:nx=4,ny=4 -n 1 -o " + dir.path().string());
  ASSERT_EQ(r.status, 0) << r.out;
  EXPECT_NE(r.out.find("detector kdop"), std::string::npos) << r.out;
}

// Defect 8 (CLI): detect and compare take a folder of frames, as render and the viewer do.
TEST(Safety, DetectAndCompareTakeAFolderOfFrames) {
  const testing::TempDir dir;
  const TriMesh folded = shapes::folded_cloth();
  const TriMesh flat = shapes::lattice(32, 32);
  io::write_obj(dir / "001.obj", folded.positions(), folded.topology().faces());
  io::write_obj(dir / "000.obj", flat.positions(), folded.topology().faces());
  auto r = run_cli("detect " + dir.path().string() + " -t 0.02");
  ASSERT_EQ(r.status, 0) << r.out;
  EXPECT_NE(r.out.find("frame 0  " + (dir / "000.obj").string() + "  vf 0 "), std::string::npos)
      << r.out;
  EXPECT_NE(r.out.find("frame 1  " + (dir / "001.obj").string()), std::string::npos) << r.out;
  r = run_cli("compare " + dir.path().string() + " -t 0.02");
  ASSERT_EQ(r.status, 0) << r.out;
  EXPECT_NE(r.out.find("summary  frames 2"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("missed 0"), std::string::npos) << r.out;
  r = run_cli("detect " + (dir / "empty").string());
  EXPECT_EQ(r.status, 1) << r.out;
}

// Progress: a plain line with an ETA on stderr when it is not a terminal (here: a pipe).
TEST(Safety, ProgressIsAPlainLineWithAnEtaOffTerminal) {
  const testing::TempDir dir;
  auto r = testing::run_program("CRUMPLE_PROGRESS_SECONDS=0 " + std::string(CRUMPLE_CLI),
                                "simulate hanging-cloth:nx=4,ny=4 -n 3 -o " + dir.path().string());
  ASSERT_EQ(r.status, 0) << r.out;
  EXPECT_NE(r.out.find("crumple simulate: frame 3/3, "), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("ETA"), std::string::npos) << r.out;
  // Issue 43: the run reports its frames per second as it goes and in its summary.
  EXPECT_NE(r.out.find(" fps"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("frames per second"), std::string::npos) << r.out;
  EXPECT_EQ(r.out.find('\r'), std::string::npos) << "no terminal redraws in a log";
  // Short runs stay quiet by default.
  r = run_cli("simulate hanging-cloth:nx=4,ny=4 -n 3 --force -o " + dir.path().string());
  ASSERT_EQ(r.status, 0) << r.out;
  EXPECT_EQ(r.out.find("ETA"), std::string::npos) << r.out;
  // So do render (a scene's frames, and a video's) and detect over several frames.
  const std::string progress = "CRUMPLE_PROGRESS_SECONDS=0 " + std::string(CRUMPLE_CLI);
  r = testing::run_program(progress, "render hanging-cloth:nx=4,ny=4 --frame 3 --size 40x30 --out " +
                                         (dir / "f.png").string());
  ASSERT_EQ(r.status, 0) << r.out;
  EXPECT_NE(r.out.find("crumple render: frame 3/4, "), std::string::npos) << r.out;  // frames done
  EXPECT_NE(r.out.find("crumple render: frame 4/4, "), std::string::npos) << r.out;  // and the end
  EXPECT_NE(r.out.find("ETA"), std::string::npos) << r.out;
  r = testing::run_program(progress, "detect " + (dir / "frames").string() + " -t 0.01");
  ASSERT_EQ(r.status, 0) << r.out;
  EXPECT_NE(r.out.find("crumple detect: frame 4/4, "), std::string::npos) << r.out;
}

// Fuzzing in CI: a missing fuzz binary printed a sed error and was reported as a finding (or
// `fuzz.sh TARGET` exited 2 with the sed error only). It is one clear line naming what to
// build, exit 2, and nothing runs, even when the other targets are built.
TEST(Safety, FuzzScriptWithoutItsBinariesSaysWhatToBuild) {
  const testing::TempDir dir;
  const auto bin = dir / "tests" / "fuzz";
  std::filesystem::create_directories(bin);
  {
    std::ofstream fake(bin / "fuzz_obj");
    fake << "#!/bin/sh\necho RAN >&2\n";
  }
  std::filesystem::permissions(bin / "fuzz_obj", std::filesystem::perms::owner_all);
  const std::string script = "FUZZ_BUILD=" + quoted(dir.path()) + " bash " +
                             quoted(std::filesystem::path(CRUMPLE_SOURCE_DIR) / "scripts" / "fuzz.sh");
  for (const std::string& args : {std::string("ci 1"), std::string("ply 1 ") + (dir / "work").string()}) {
    const auto r = testing::run_program(script, args);
    EXPECT_EQ(r.status, 2) << args << "\n" << r.out;
    EXPECT_NE(r.out.find("fuzz.sh: not built: " + (bin / "fuzz_ply").string()), std::string::npos)
        << args << "\n" << r.out;
    EXPECT_NE(r.out.find("cmake --preset fuzz"), std::string::npos) << args << "\n" << r.out;
    EXPECT_EQ(r.out.find("sed:"), std::string::npos) << args << "\n" << r.out;
    EXPECT_EQ(r.out.find("RAN"), std::string::npos) << "nothing runs: " << args << "\n" << r.out;
    EXPECT_EQ(r.out.find("fuzz_obj:"), std::string::npos) << args << "\n" << r.out;
  }
}

}  // namespace
}  // namespace crumple
