// crumple: command-line front end. Parses arguments, calls the library, prints results.
#include "commands.hpp"

#include <crumple/core/error.hpp>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <iostream>
#include <map>

namespace {

/// Flushes and closes stdout: output that never reached its file (a full disk, a closed pipe)
/// is an error, reported like any other. Returns false after printing the reason.
bool close_stdout() {
  // std::cout writes straight into stdout's buffer (synchronised with stdio).
  errno = 0;
  const bool flushed = std::fflush(stdout) == 0 && !std::ferror(stdout);
  const int flush_errno = errno;  // 0 when the failure came from an earlier flush
  std::cout.flush();
  const bool stream_ok = static_cast<bool>(std::cout);
  const bool closed = std::fclose(stdout) == 0;
  if (stream_ok && flushed && closed) return true;
  const int err = flush_errno != 0 ? flush_errno : errno;
  std::fprintf(stderr, "crumple: error: cannot write the standard output: %s\n",
               err != 0 ? std::strerror(err) : "write error");
  return false;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{
      "crumple — real-time self-collision detection on highly deformable meshes.\n"
      "Run `crumple <command> --help` for the options of a command."};
  app.require_subcommand(1);
  app.set_version_flag("--version", "crumple 0.1.0");

  std::map<CLI::App*, crumple::cli::Run> commands;
  const auto add = [&](const char* name, const char* summary, auto adder) {
    CLI::App* sub = app.add_subcommand(name, summary);
    commands[sub] = adder(*sub);
  };
  add("detect", "Detect self-contacts on one mesh or a sequence of frames",
      crumple::cli::add_detect_command);
  add("compare", "Measure a method's recall, false contacts and time against a reference",
      crumple::cli::add_compare_command);
  add("info", "Print counts, bounds, edge lengths and the validation report of a mesh",
      crumple::cli::add_info_command);
  add("simulate", "Simulate a cloth scene or model with self-collision detection and response",
      crumple::cli::add_simulate_command);
  add("bench", "Reproduce the thesis' Figure 4.2/4.3 benchmarks and write tables and plots",
      crumple::cli::add_bench_command);
  add("render", "Render a scene, a mesh or frames to PNG with colliding edges in red",
      crumple::cli::add_render_command);
  add("ccd", "Continuous collision detection between two frames, or narrow-phase queries from a file",
      crumple::cli::add_ccd_command);

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int code = app.exit(e);  // --help and --version print here too
    return !close_stdout() && code == 0 ? 1 : code;
  }
  int status = 0;
  try {
    for (auto& [sub, run] : commands) {
      if (sub->parsed()) status = run();
    }
  } catch (const crumple::Error& e) {
    std::cout.flush();
    std::cerr << "crumple: error: " << e.what() << "\n";
    status = 1;
  } catch (const std::filesystem::filesystem_error& e) {
    // The file system's refusal (permissions, full disk, a file where a folder should be) is
    // the user's to fix: its message names the path and the OS's reason.
    std::cout.flush();
    std::cerr << "crumple: error: " << e.what() << "\n";
    status = 1;
  } catch (const std::bad_alloc&) {
    std::cout.flush();
    std::cerr << "crumple: error: out of memory\n";
    status = 1;
  } catch (const std::exception& e) {
    std::cout.flush();
    std::cerr << "crumple: internal error: " << e.what() << "\n";
    status = 2;
  }
  if (!close_stdout() && status == 0) status = 1;
  return status;
}
