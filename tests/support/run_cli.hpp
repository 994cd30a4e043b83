#pragma once
// Runs the `crumple` binary (path in the CRUMPLE_CLI macro), or another program, as a user would,
// for the CLI tests.

#include <array>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>
#include <vector>
#include <fcntl.h>
#include <sys/wait.h>
#include <unistd.h>

namespace crumple::testing {

struct CliResult {
  int status;       ///< exit status, -1 when the program did not exit normally
  std::string out;  ///< stdout and stderr together
};

/// Runs `PROGRAM ARGS` through the shell and collects its output.
inline CliResult run_program(const std::string& program, const std::string& args) {
  const std::string command = program + " " + args + " 2>&1";
  FILE* pipe = ::popen(command.c_str(), "r");
  if (!pipe) return {-1, ""};
  std::string out;
  std::array<char, 4096> buffer;
  while (std::size_t n = std::fread(buffer.data(), 1, buffer.size(), pipe)) out.append(buffer.data(), n);
  const int raw = ::pclose(pipe);
  return {WIFEXITED(raw) ? WEXITSTATUS(raw) : -1, out};
}

/// Runs `crumple ARGS` through the shell and collects its output.
inline CliResult run_cli(const std::string& args) { return run_program(CRUMPLE_CLI, args); }

/// The lines of a text file a command wrote (empty when it cannot be read).
inline std::vector<std::string> read_lines(const std::filesystem::path& path) {
  std::ifstream in(path);
  std::vector<std::string> lines;
  for (std::string line; std::getline(in, line);) lines.push_back(line);
  return lines;
}

/// Runs `crumple simulate hanging-cloth:nx=6,ny=6 --frames 1000000 -o DIR EXTRA...` (its
/// output discarded) until DIR/stats.csv holds 10 lines (at most 60 s), then sends it `signal`
/// and waits. Returns its exit status, or -1 when it did not exit normally (killed by the
/// signal).
inline int interrupt_simulation(const std::filesystem::path& dir, int signal, const std::vector<std::string>& extra = {}) {
  std::vector<std::string> args{CRUMPLE_CLI, "simulate", "hanging-cloth:nx=6,ny=6", "--frames", "1000000",
                                "-o",        dir.string()};
  args.insert(args.end(), extra.begin(), extra.end());
  std::vector<char*> argv;
  for (std::string& a : args) argv.push_back(a.data());
  argv.push_back(nullptr);
  const pid_t pid = ::fork();
  if (pid < 0) return -2;
  if (pid == 0) {
    const int null = ::open("/dev/null", O_WRONLY);
    ::dup2(null, 1);
    ::dup2(null, 2);
    ::execv(CRUMPLE_CLI, argv.data());
    ::_exit(127);
  }
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
  while (read_lines(dir / "stats.csv").size() < 10 && std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  ::kill(pid, signal);
  int status = 0;
  ::waitpid(pid, &status, 0);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

}  // namespace crumple::testing
