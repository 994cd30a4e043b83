#pragma once
// Runs the `crumple` binary (path in the CRUMPLE_CLI macro), or another program, as a user would,
// for the CLI tests.

#include <array>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>
#include <sys/wait.h>

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

}  // namespace crumple::testing
