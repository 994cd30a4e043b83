// `crumple ccd FRAME0 FRAME1`: continuous collision detection of a mesh over one step (impacts,
// earliest time of impact, counts, ms by phase); `crumple ccd --queries FILE`: the narrow
// phase on a file of queries, one answer a line.
#include "commands.hpp"
#include "options.hpp"
#include "outputs.hpp"

#include <crumple/core/error.hpp>
#include <crumple/core/json.hpp>
#include <crumple/core/timing.hpp>
#include <crumple/detect/continuous.hpp>
#include <crumple/geometry/ccd.hpp>
#include <crumple/io/ccd_queries.hpp>
#include <crumple/io/frames.hpp>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace crumple::cli {

namespace {
struct CcdArgs {
  std::vector<std::string> frames;
  std::string queries;
  std::optional<double> min_separation;
  std::optional<double> min_separation_rel;
  std::string method = kDefaultMethod;
  int threads = 0;
  std::string impacts;
  bool json = false;
  double time_tolerance = 1e-6;
  long long max_boxes = 10000;
  bool stats = false;
};

/// The narrow phase's range for δ (`geometry::ccd`'s precondition), as an input error.
void check_min_separation(double delta) {
  if (!(delta >= 0 && delta <= 0x1p1000)) {
    char text[64];
    std::snprintf(text, sizeof text, "%.17g", delta);
    throw InputError(std::string("ccd: the minimum separation must be in [0, 2^1000], got ") + text);
  }
}

int run_queries(const CcdArgs& args) {
  if (args.min_separation_rel) throw InputError("ccd --queries: --min-separation-rel needs frames; give --min-separation");
  check_min_separation(args.min_separation.value_or(0));
  const std::vector<io::CcdQuery> queries = io::read_ccd_queries(args.queries);
  geometry::CcdOptions options;
  options.min_separation = args.min_separation.value_or(0);
  options.time_tolerance = args.time_tolerance;
  options.max_boxes = args.max_boxes;
  std::map<std::string, long long> outcomes;
  for (const io::CcdQuery& q : queries) {
    const geometry::CcdResult r = geometry::ccd(q.pair, q.start, q.end, options);
    if (r.hit) {
      std::printf("1 %.17g\n", r.toi);
    } else {
      std::printf("0\n");
    }
    ++outcomes[std::string(geometry::to_string(r.outcome))];
  }
  if (args.stats) {
    std::fflush(stdout);
    for (const auto& [name, n] : outcomes) std::fprintf(stderr, "%s %lld\n", name.c_str(), n);
  }
  return 0;
}

int run_frames(const CcdArgs& args) {
  if (args.frames.size() != 2) {
    throw InputError("ccd: give two frames FRAME0 FRAME1 (got " + std::to_string(args.frames.size()) +
                     ") or --queries FILE");
  }
  if (args.threads < 0 || args.threads > kMaxThreads) {
    throw InputError("ccd: --threads must be in 0.." + std::to_string(kMaxThreads));
  }
  if (!args.impacts.empty()) check_output_file(args.impacts, "--impacts");
  const MethodSpec spec = MethodSpec::parse(args.method);
  // The second frame must have the first's vertex count and faces (ParseError names the file).
  const io::FrameSequence frames({args.frames[0], args.frames[1]});
  const TriMesh& mesh = frames.first();
  const Positions x1 = frames.positions(1);
  Scalar delta = 0;
  if (args.min_separation) {
    delta = *args.min_separation;
  } else if (args.min_separation_rel) {
    delta = *args.min_separation_rel * compute_bounds(mesh.positions()).diagonal();
  }
  check_min_separation(delta);
  ContinuousOptions options;
  options.min_separation = delta;
  options.method = spec;
  options.threads = args.threads;
  options.narrow.time_tolerance = args.time_tolerance;
  options.narrow.max_boxes = args.max_boxes;
  const auto start = std::chrono::steady_clock::now();
  ContinuousQuery query(mesh.topology_ptr(), options);
  const double setup_ms = ms_since(start);
  ImpactSet impacts;
  query.query(mesh.positions(), x1, impacts);
  const double query_ms = ms_since(start) - setup_ms;
  const DetectorStats& st = query.stats();
  const Scalar step = collision_free_step(impacts);
  const auto count = [&](const char* key) { return static_cast<long long>(st.get(key)); };
  if (args.json) {
    JsonObject stats;
    for (const auto& [key, value] : st.items()) stats.add(key, value);
    std::cout << JsonObject()
                     .add("frame0", args.frames[0])
                     .add("frame1", args.frames[1])
                     .add("vertices", static_cast<long long>(mesh.num_vertices()))
                     .add("faces", static_cast<long long>(mesh.num_faces()))
                     .add("method", spec.to_string())
                     .add("min_separation", delta)
                     .add("threads", args.threads)
                     .add("earliest_toi", step)
                     .add("vf_impacts", impacts.vf.size())
                     .add("ee_impacts", impacts.ee.size())
                     .add("setup_ms", setup_ms)
                     .add("query_ms", query_ms)
                     .add_raw("stats", stats.str())
                     .str()
              << std::endl;
  } else {
    std::printf("ccd %s -> %s: %d vertices, %d faces, method %s, min separation %.6g\n", args.frames[0].c_str(),
                args.frames[1].c_str(), mesh.num_vertices(), mesh.num_faces(), spec.to_string().c_str(), delta);
    std::printf("earliest toi %.17g%s\n", step, impacts.empty() ? " (no impact: full step)" : "");
    std::printf("candidates %lld  box-rejected vf %lld ee %lld  narrow tests vf %lld ee %lld  orphans vf %lld ee %lld\n",
                count("candidates"), count("vf_box_rejected"), count("ee_box_rejected"), count("vf_tests"),
                count("ee_tests"), count("orphan_vf"), count("orphan_ee"));
    std::printf("impacts vf %zu ee %zu  conservative-only %lld (budget, precision or range: possible false positives)\n",
                impacts.vf.size(), impacts.ee.size(), count("conservative_hits"));
    std::printf("ms: setup %.3f  update %.3f  stream %.3f (narrow thread time %.3f)  orphans %.3f  sort %.3f  total %.3f\n",
                setup_ms, st.get("update_ms"), st.get("stream_ms"), st.get("narrow_cpu_ms"), st.get("orphan_ms"),
                st.get("sort_ms"), st.get("total_ms"));
    std::fflush(stdout);
  }
  if (!args.impacts.empty()) write_impacts_file(args.impacts, impacts);
  return 0;
}
}  // namespace

Run add_ccd_command(CLI::App& app) {
  auto args = std::make_shared<CcdArgs>();
  app.description(
      "Continuous collision detection. With FRAME0 FRAME1 (two frames of one mesh, vertices moving\n"
      "linearly between them): every vertex-face and edge-edge pair sharing no vertex that comes\n"
      "within the minimum separation during the step, with a conservative time of impact; prints\n"
      "the earliest one (the collision-free step), counts and ms by phase. With --queries FILE:\n"
      "the narrow phase on one query a line.");
  app.add_option("FRAME", args->frames, "Two frame files FRAME0 FRAME1 (same vertices and faces)");
  app.add_option("--queries", args->queries,
                 "Query file: per line 'vf' or 'ee' then the 4 points at t=0 and at t=1 (24 numbers, "
                 "decimal or hex floats). Prints '1 TOI' or '0' per query");
  auto* abs = app.add_option("-d,--min-separation", args->min_separation, "Minimum separation delta >= 0 (default 0)")
                  ->check(CLI::NonNegativeNumber);
  app.add_option("--min-separation-rel", args->min_separation_rel,
                 "Minimum separation as a multiple of FRAME0's bounding-box diagonal")
      ->check(CLI::NonNegativeNumber)
      ->excludes(abs);
  app.add_option("-m,--method", args->method, "Broad phase: kdop (always swept), hash or sap, with parameters as "
                                              "for detect (default kdop)");
  app.add_option("-j,--threads", args->threads, "Worker threads (0 = all hardware threads)");
  app.add_option("--impacts", args->impacts,
                 "Write the sorted impacts to this file (atomically). Lines: 'vf V F toi w0 w1 w2 nx ny nz', "
                 "'ee A0 A1 B0 B1 toi s t nx ny nz'");
  app.add_flag("--json", args->json,
               "Print one JSON object: frames, counts, earliest_toi, impacts, ms, stats");
  app.add_option("--time-tolerance", args->time_tolerance, "Time tolerance of the reported TOI (default 1e-6)")
      ->check(CLI::PositiveNumber);
  app.add_option("--max-boxes", args->max_boxes, "Box budget per query before a conservative hit (default 10000)")
      ->check(CLI::PositiveNumber);
  app.add_flag("--stats", args->stats, "With --queries: print the count of each outcome to stderr");
  return [args]() {
    if (!args->queries.empty()) {
      if (!args->frames.empty()) throw InputError("ccd: give either FRAME0 FRAME1 or --queries FILE, not both");
      return run_queries(*args);
    }
    return run_frames(*args);
  };
}

}  // namespace crumple::cli
