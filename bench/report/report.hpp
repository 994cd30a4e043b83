#pragma once
// The report of `crumple bench`: the thesis' Figure 4.2 (frames per second against the share of
// the surface in collision) and Figure 4.3 (pairs missed), its second test (a 100×10 strip), the
// scaling to large lattices and the real meshes, and the stochastic detector's recall against
// its time per frame, written as CSV, JSON, markdown and SVG plots. The command line lives in
// apps/cli/bench_command.cpp.

#include <array>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

namespace crumple::bench {

/// The report's sections, in the order they run.
inline constexpr std::array<const char*, 4> kReportSections = {"thesis", "second", "scaling",
                                                                "budget"};

struct ReportOptions {
  bool quick = false;  ///< tiny inputs: checks the pipeline, figures meaningless
  int repeat = 3;      ///< runs per frame; the median is kept
  std::vector<std::string> sections;  ///< of kReportSections; empty = all
  std::string data;                   ///< folder of the real meshes
  long long max_lattice = 1000;       ///< largest n of the n×n scaling lattices
  std::uint64_t seed = 1;             ///< seed of the scenes' perturbations
  int threads = 1;                    ///< threads per detector
};

/// Called before each step: sections finished so far, the section, what runs now.
using ReportProgress =
    std::function<void(std::size_t sections_done, const std::string& section, const std::string& step)>;

struct ReportResult {
  std::string machine, commit;
  std::vector<std::string> headline;  ///< the key figures, one line each
  std::size_t tables = 0, plots = 0;
};

/// Runs the sections and writes bench.md, bench.json, one CSV per table and the SVG plots into
/// the existing folder `out` (atomically, at the end).
ReportResult write_report(const ReportOptions& options, const std::filesystem::path& out,
                          const ReportProgress& progress);

}  // namespace crumple::bench
