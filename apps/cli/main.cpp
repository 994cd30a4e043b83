// crumple: command-line front end. Parses arguments, calls the library, prints results.
#include "commands.hpp"

#include <crumple/core/error.hpp>

#include <iostream>
#include <map>

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
  add("ccd", "Continuous collision detection: narrow-phase queries from a file", crumple::cli::add_ccd_command);

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  }
  try {
    for (auto& [sub, run] : commands) {
      if (sub->parsed()) return run();
    }
  } catch (const crumple::Error& e) {
    std::cerr << "crumple: error: " << e.what() << "\n";
    return 1;
  } catch (const std::exception& e) {
    std::cerr << "crumple: internal error: " << e.what() << "\n";
    return 2;
  }
  return 0;
}
