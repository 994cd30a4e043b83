// `crumple bench`: the command line of the benchmark report (bench/report/report.hpp): checks
// the output folder first, shows progress, prints the headline figures.
#include "commands.hpp"
#include "outputs.hpp"
#include "progress.hpp"

#include <report/report.hpp>

#include <crumple/core/error.hpp>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#ifndef CRUMPLE_DEFAULT_DATA_DIR
#define CRUMPLE_DEFAULT_DATA_DIR "../shared/data"
#endif

namespace crumple::cli {
namespace {

struct Args {
  Args() { report.data = CRUMPLE_DEFAULT_DATA_DIR; }
  std::string out = "crumple-bench";
  bench::ReportOptions report;
  bool quiet = false;
};

/// Whether `folder` holds a full (not --quick) report.
bool holds_full_report(const std::filesystem::path& folder) {
  std::ifstream in(folder / "bench.json");
  if (!in) return false;
  std::stringstream text;
  text << in.rdbuf();
  const std::string s = text.str();
  return s.find("\"quick\":false") != std::string::npos ||
         s.find("\"quick\": false") != std::string::npos;
}

/// Checks the output folder up front, so a bad `--out` fails before minutes of measurements:
/// writable, and never a full report about to be replaced by a --quick one.
void prepare_output(const Args& args) {
  if (args.report.quick && holds_full_report(args.out)) {
    throw InputError("--out '" + args.out +
                     "' holds a full report (bench.json): --quick never replaces one; give "
                     "another --out");
  }
  prepare_output_folder(args.out, "--out");
}

int run(const Args& args) {
  prepare_output(args);
  const std::size_t sections =
      args.report.sections.empty() ? bench::kReportSections.size() : args.report.sections.size();
  Progress progress("bench", "section", sections, !args.quiet);
  const bench::ReportResult result = bench::write_report(
      args.report, args.out,
      [&](std::size_t done, const std::string& section, const std::string& step) {
        progress.update(done, "[" + section + "] " + step);
      });
  progress.finish();
  if (!args.quiet) {
    std::printf("crumple bench: %s, commit %s\n", result.machine.c_str(), result.commit.c_str());
    for (const std::string& line : result.headline) std::printf("  %s\n", line.c_str());
    std::printf("  wrote %s/bench.{md,json}, %zu CSV tables and %zu SVG plots\n", args.out.c_str(),
                result.tables, result.plots);
  }
  return 0;
}

}  // namespace

Run add_bench_command(CLI::App& app) {
  auto args = std::make_shared<Args>();
  app.description(
      "Reproduce the thesis' benchmarks on crumple's detectors and write a report.\n"
      "Sections: thesis (Figure 4.2: fps against the share of the surface in collision on the\n"
      "hanging cloth, every method on the same recorded frames, edge-edge then VF+EE; Figure 4.3:\n"
      "pairs missed above 80%), second (the 100x10 strip with 300 active pairs), scaling (folding\n"
      "lattices up to --max-lattice and the real meshes of --data), budget (the stochastic\n"
      "detector's recall against time per frame). Writes bench.md, bench.json, one CSV per table\n"
      "and SVG plots into --out. The full run takes about 10 minutes on 2 cores.");
  app.add_option("-o,--out", args->out,
                 "Output folder (created); the repository's report is docs/benchmarks")
      ->capture_default_str();
  app.add_flag("--quick", args->report.quick,
               "Every section on tiny inputs (seconds): checks the whole pipeline, figures "
               "meaningless; never replaces a full report");
  app.add_option("--sections", args->report.sections, "Sections to run (default: all)")
      ->delimiter(',')
      ->check(CLI::IsMember(std::vector<std::string>(bench::kReportSections.begin(), bench::kReportSections.end())));
  app.add_option("--repeat", args->report.repeat, "Runs per frame; the median is kept")
      ->capture_default_str()
      ->check(CLI::Range(1, 100));
  app.add_option("--threads", args->report.threads, "Threads per detector (the thesis: 1; 0 = all)")
      ->capture_default_str()
      ->check(CLI::Range(0, 1024));
  app.add_option("--max-lattice", args->report.max_lattice, "Largest n of the n×n scaling lattices")
      ->capture_default_str()
      ->check(CLI::Range(4, 1000));
  app.add_option("--data", args->report.data, "Folder of the real meshes (../shared/data)")->capture_default_str();
  app.add_option("--seed", args->report.seed, "Seed of the scenes' perturbations")->capture_default_str();
  app.add_flag("-q,--quiet", args->quiet, "No progress line or summary");
  return [args] { return run(*args); };
}

}  // namespace crumple::cli
