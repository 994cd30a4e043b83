// Runs `sim_bench --check-frames` (bench/sim_bench.cpp, built with the benchmarks) as a long run is
// run: a progress line at the set period, and a summary however the run ends (every frame run, a
// divergence, a signal such as `timeout`'s SIGTERM), so that a stopped run still says how far it
// got and what it saw.
#ifdef CRUMPLE_SIM_BENCH

#include <support/run_cli.hpp>
#include <support/temp_dir.hpp>

#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdlib>
#include <fstream>
#include <iterator>
#include <string>
#include <thread>
#include <fcntl.h>
#include <sys/wait.h>
#include <unistd.h>

namespace crumple {
namespace {

/// `sim_bench --check-frames=ARGS` with a progress line after every frame.
testing::CliResult check(const std::string& args) {
  return testing::run_program("CRUMPLE_PROGRESS_SECONDS=0 " + std::string(CRUMPLE_SIM_BENCH), "--check-frames=" + args);
}

bool has(const std::string& text, const std::string& part) { return text.find(part) != std::string::npos; }

/// The number after `label` in `line` (NaN when absent).
double number_after(const std::string& line, const std::string& label) {
  const std::size_t at = line.find(label);
  if (at == std::string::npos) return std::nan("");
  return std::strtod(line.c_str() + at + label.size(), nullptr);
}

std::string line_with(const std::string& text, const std::string& start) {
  const std::size_t at = text.find(start);
  if (at == std::string::npos) return {};
  return text.substr(at, text.find('\n', at) - at);
}

TEST(SimBenchCheckFrames, CleanRunReportsProgressEveryPeriodAndASummary) {
  const testing::CliResult r = check("cloth-on-sphere:n=4 --frames=3 --threads=1");
  EXPECT_EQ(r.status, 0) << r.out;
  for (int f = 1; f <= 3; ++f) {
    EXPECT_TRUE(has(r.out, "progress cloth-on-sphere:n=4: frame " + std::to_string(f) + " of 3,")) << r.out;
  }
  const std::string summary = line_with(r.out, "summary cloth-on-sphere:n=4: ");
  EXPECT_TRUE(has(summary, ": 3 frames run of 3, 0 with intersections")) << r.out;
  EXPECT_FALSE(has(summary, "STOPPED")) << summary;
  // The cloth falls freely for 3 frames: its springs barely stretch (and never shrink to nothing).
  const double stretch = number_after(summary, "longest spring ");
  EXPECT_GT(stretch, 0.9) << summary;
  EXPECT_LT(stretch, 1.5) << summary;
  EXPECT_GT(number_after(summary, "fastest "), 0) << summary;
}

TEST(SimBenchCheckFrames, StepOptionsReachTheSimulation) {
  const testing::CliResult defaults = check("cloth-on-sphere:n=4 --frames=1 --threads=1");
  EXPECT_TRUE(has(defaults.out, "projective (rho 0.8, 5 iterations, settle 0 m), 4 steps of 0.004167 s")) << defaults.out;
  const testing::CliResult set =
      check("cloth-on-sphere:n=4 --frames=1 --threads=1 --rho=0 --iterations=7 --settle=0.5 --substeps=2");
  EXPECT_EQ(set.status, 0) << set.out;
  EXPECT_TRUE(has(set.out, "projective (rho 0, 7 iterations, settle ")) << set.out;
  EXPECT_TRUE(has(set.out, "), 2 steps of 0.008333 s")) << set.out;
}

TEST(SimBenchCheckFrames, IntersectingFramesAreListedAndFailTheRun) {
  // The thesis scene without response falls through itself (docs/simulation.md): the 6x6 cloth's
  // folds pass through each other within 60 frames.
  const testing::CliResult r = check("hanging-cloth:nx=6,ny=6 --frames=60 --threads=1");
  EXPECT_EQ(r.status, 1) << r.out;
  const std::string summary = line_with(r.out, "summary hanging-cloth:nx=6,ny=6: ");
  EXPECT_TRUE(has(summary, ": 60 frames run of 60, ")) << r.out;
  const double bad = number_after(summary, "of 60, ");
  EXPECT_GE(bad, 1) << summary;
  EXPECT_TRUE(has(r.out, " intersecting pairs\n")) << r.out;
}

TEST(SimBenchCheckFrames, DivergenceEndsWithASummary) {
  // Gravity of 1e4 m/s^2 stretches the 2x2 cloth past 10 times its size within a few frames.
  const testing::CliResult r = check("hanging-cloth:nx=2,ny=2,gravity=1e4 --frames=50 --threads=1");
  EXPECT_EQ(r.status, 1) << r.out;
  const std::string summary = line_with(r.out, "summary hanging-cloth:nx=2,ny=2,gravity=1e4: ");
  EXPECT_TRUE(has(summary, "STOPPED: DIVERGED: the simulation diverged at frame ")) << r.out;
  const double run = number_after(summary, ": ");
  EXPECT_GE(run, 1) << summary;
  EXPECT_LT(run, 50) << summary;
  // Every frame before the divergence had its progress line, the last one included.
  for (int f = 1; f <= run; ++f) {
    EXPECT_TRUE(has(r.out, ": frame " + std::to_string(f) + " of 50,")) << r.out;
  }
  EXPECT_NE(number_after(summary, "diverged at frame "), 0) << summary;
  EXPECT_EQ(number_after(summary, "diverged at frame "), run + 1) << summary;
}

TEST(SimBenchCheckFrames, SigtermStopsAfterTheFrameWithASummary) {
  const testing::TempDir dir;
  const std::string log = (dir / "log.txt").string();
  const pid_t pid = ::fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    const int out = ::open(log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    ::dup2(out, 1);
    ::dup2(out, 2);
    ::setenv("CRUMPLE_PROGRESS_SECONDS", "0", 1);
    ::execl(CRUMPLE_SIM_BENCH, CRUMPLE_SIM_BENCH, "--check-frames=cloth-on-sphere:n=4", "--frames=100000000",
            "--threads=1", static_cast<char*>(nullptr));
    ::_exit(127);
  }
  const auto read_log = [&] {
    std::ifstream in(log);
    return std::string(std::istreambuf_iterator<char>(in), {});
  };
  // Wait for a progress line past frame 1: the output reaches the file line by line.
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
  while (!has(read_log(), "frame 2 of 100000000") && std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  ::kill(pid, SIGTERM);
  int status = 0;
  ::waitpid(pid, &status, 0);
  const std::string out = read_log();
  ASSERT_TRUE(WIFEXITED(status)) << "killed by the signal\n" << out;
  EXPECT_EQ(WEXITSTATUS(status), 3) << out;
  const std::string summary = line_with(out, "summary cloth-on-sphere:n=4: ");
  EXPECT_TRUE(has(summary, "STOPPED: SIGTERM")) << out;
  EXPECT_GE(number_after(summary, ": "), 2) << summary;
}

TEST(SimBenchCheckFrames, BadArgumentsAreClearErrors) {
  struct Case {
    std::string args, says;
  };
  for (const Case& c : {Case{"cloth-on-sphere:n=4 --frames=abc", "'--frames=abc' expects a number"},
                        Case{"cloth-on-sphere:n=4 --frames=0", "--frames expects an integer >= 1"},
                        Case{"cloth-on-sphere:n=4 --rho=1", "--rho expects a number in [0, 1)"},
                        Case{"cloth-on-sphere:n=4 --threads=-1", "--threads expects an integer >= 0"},
                        Case{"cloth-on-sphere:n=4 --iterations=0", "--iterations expects an integer >= 1"},
                        Case{"cloth-on-sphere:n=4 --settle=-1", "--settle expects a number >= 0"},
                        Case{"cloth-on-sphere:n=4 --substeps=2.5", "--substeps expects an integer >= 1"},
                        Case{"cloth-on-sphere:n=4 --bogus", "unknown argument '--bogus'"},
                        Case{"bogus-scene", "unknown scene 'bogus-scene'"},
                        Case{"cloth-on-sphere:n=0", "key 'n' must be between 1"}}) {
    const testing::CliResult r = check(c.args);
    EXPECT_EQ(r.status, 2) << c.args << "\n" << r.out;
    EXPECT_TRUE(has(r.out, c.says)) << c.args << "\n" << r.out;
  }
}

}  // namespace
}  // namespace crumple

#endif  // CRUMPLE_SIM_BENCH
