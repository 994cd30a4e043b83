// Mesh-level continuous collision detection (detect/continuous.hpp) on the five real frame
// pairs of ../shared/data/sample-scalable-ccd, at δ = 0 and δ = 1e-3 × the first frame's
// bounding-box diagonal, with 1 and 2 threads.
//
// Per run, after one untimed warm-up query (the first query after construction pays page faults
// and the first refit): the broad phase alone (`ContinuousQuery::count_candidates`: refit or
// sort, then the candidate stream counted and dropped) and the whole query, alternated
// `--repeat` times, the fastest of each kept; whole CPU ms, the least process CPU time (all
// threads) of the whole queries; narrow ms, the narrow phase's thread time inside the stream
// (summed per chunk on the broad phase's threads) divided by the thread count, so never
// negative (whole − broad was, on a noisy machine); orphan ms (the orphan sub-pairs, stars and
// isolated vertices after the stream); candidates, narrow-phase tests, impacts,
// conservative-only hits, the earliest TOI, the time of `ContinuousQuery::collision_free_step`
// alone (checked equal to the impacts' earliest TOI) and the process's peak resident memory
// during the run (VmHWM, reset before each run through /proc/self/clear_refs).
//
//   ccd_mesh_bench [--data DIR] [--scenes a,b] [--threads 1,2] [--deltas 0,1e-3] [--repeat N] [--method kdop]
//                  [--json FILE] [--markdown FILE]
// `--deltas` are relative to the first frame's bounding-box diagonal (default 0,1e-3).
#include <crumple/core/error.hpp>
#include <crumple/core/json.hpp>
#include <crumple/core/timing.hpp>
#include <crumple/detect/continuous.hpp>
#include <crumple/io/mesh_io.hpp>

#include <algorithm>
#include <chrono>
#include <ctime>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

using namespace crumple;

namespace {

struct Scene {
  const char* name;
  const char* frame0;
  const char* frame1;
};

// Smallest first.
const Scene kScenes[] = {
    {"cloth-funnel", "cloth-funnel/frames/227.ply", "cloth-funnel/frames/228.ply"},
    {"armadillo", "armadillo-rollers/frames/326.ply", "armadillo-rollers/frames/327.ply"},
    {"rod-twist", "rod-twist/frames/3036.ply", "rod-twist/frames/3037.ply"},
    {"n-body", "n-body-simulation/frames/balls16_18.ply", "n-body-simulation/frames/balls16_19.ply"},
    {"cloth-ball", "cloth-ball/frames/cloth_ball92.ply", "cloth-ball/frames/cloth_ball93.ply"},
};

std::vector<std::string> split(const std::string& s) {
  std::vector<std::string> out;
  std::stringstream in(s);
  for (std::string item; std::getline(in, item, ',');) {
    if (!item.empty()) out.push_back(item);
  }
  return out;
}

std::string stats_json(const DetectorStats& stats) {
  JsonObject object;
  for (const auto& [key, value] : stats.items()) object.add(key, value);
  return object.str();
}

void reset_peak_rss() {
  std::ofstream("/proc/self/clear_refs") << "5";
}

/// Process CPU time (all threads), ms: on a shared machine the figure that load inflates least.
double cpu_ms() {
  timespec ts{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) * 1e3 + static_cast<double>(ts.tv_nsec) * 1e-6;
}

double peak_rss_mb() {
  std::ifstream in("/proc/self/status");
  for (std::string line; std::getline(in, line);) {
    if (line.rfind("VmHWM:", 0) == 0) return std::strtod(line.c_str() + 6, nullptr) / 1024;
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  std::string data = CRUMPLE_BENCH_DATA_DIR "/sample-scalable-ccd";
  std::vector<std::string> only, threads_list{"1", "2"}, deltas_list{"0", "1e-3"};
  int repeat = 1;
  std::string method = "kdop", json_path, markdown_path;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    const auto value = [&]() -> std::string {
      if (i + 1 >= argc) {
        std::fprintf(stderr, "ccd_mesh_bench: %s needs a value\n", a.c_str());
        std::exit(2);
      }
      return argv[++i];
    };
    if (a == "--data") data = value();
    else if (a == "--scenes") only = split(value());
    else if (a == "--threads") threads_list = split(value());
    else if (a == "--deltas") deltas_list = split(value());
    else if (a == "--repeat") repeat = std::max(1, std::atoi(value().c_str()));
    else if (a == "--method") method = value();
    else if (a == "--json") json_path = value();
    else if (a == "--markdown") markdown_path = value();
    else {
      std::fprintf(stderr,
                   "usage: ccd_mesh_bench [--data DIR] [--scenes a,b] [--threads 1,2] [--deltas 0,1e-3] [--repeat N] "
                   "[--method SPEC] [--json FILE] [--markdown FILE]\n");
      return 2;
    }
  }
  std::ostringstream json, md;
  md << "| scene | faces | delta | threads | broad ms | narrow ms | orphan ms | whole ms | whole CPU ms | "
        "step-only ms | narrow thread ms | candidates | vf tests | ee tests | impacts (vf + ee) | conservative-only | earliest toi | "
        "peak RSS MB |\n"
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n";
  std::printf("%s", md.str().c_str());
  std::fflush(stdout);
  for (const Scene& scene : kScenes) {
    if (!only.empty() && std::find(only.begin(), only.end(), scene.name) == only.end()) continue;
    TriMesh m0, m1;
    try {
      m0 = io::read_mesh(data + "/" + scene.frame0);
      m1 = io::read_mesh(data + "/" + scene.frame1);
    } catch (const Error& e) {
      std::fprintf(stderr, "ccd_mesh_bench: skipping %s: %s\n", scene.name, e.what());
      continue;
    }
    const Scalar diag = compute_bounds(m0.positions()).diagonal();
    for (const std::string& rel : deltas_list) {
      const Scalar delta = std::strtod(rel.c_str(), nullptr) * diag;
      for (const std::string& t : threads_list) {
        ContinuousOptions options;
        options.min_separation = delta;
        options.method = MethodSpec::parse(method);
        options.threads = std::atoi(t.c_str());
        reset_peak_rss();
        ContinuousQuery query(m0.topology_ptr(), options);
        ImpactSet impacts;
        query.query(m0.positions(), m1.positions(), impacts);  // warm-up
        double broad_ms = 1e300, whole_ms = 1e300, whole_cpu_ms = 1e300;
        std::size_t candidates = 0;
        DetectorStats st;
        for (int r = 0; r < repeat; ++r) {
          // Broad phase alone, then the whole query (its own broad phase included).
          const auto b0 = std::chrono::steady_clock::now();
          candidates = query.count_candidates(m0.positions(), m1.positions());
          broad_ms = std::min(broad_ms, ms_since(b0));
          const auto q0 = std::chrono::steady_clock::now();
          const double c0 = cpu_ms();
          query.query(m0.positions(), m1.positions(), impacts);
          const double ms = ms_since(q0);
          whole_cpu_ms = std::min(whole_cpu_ms, cpu_ms() - c0);
          if (ms < whole_ms) {
            whole_ms = ms;
            st = query.stats();
          }
        }
        const double rss = peak_rss_mb();
        const double narrow_ms = st.get("narrow_cpu_ms") / std::max(1, options.threads);
        // The collision-free step alone (narrow phase pruned by the running minimum).
        const auto s0 = std::chrono::steady_clock::now();
        const Scalar step_only = query.collision_free_step(m0.positions(), m1.positions());
        const double step_ms = ms_since(s0);
        if (step_only != collision_free_step(impacts)) {
          std::fprintf(stderr, "ccd_mesh_bench: %s: collision_free_step %.17g differs from the impacts' %.17g\n",
                       scene.name, step_only, collision_free_step(impacts));
          return 1;
        }
        char line[1024];
        std::snprintf(line, sizeof line,
                      "| %s | %d | %.4g | %s | %.1f | %.1f | %.1f | %.1f | %.1f | %.1f | %.1f | %zu | %.0f | %.0f | %zu + %zu | "
                      "%.0f | %.6g | %.0f |\n",
                      scene.name, m0.num_faces(), delta, t.c_str(), broad_ms, narrow_ms, st.get("orphan_ms"), whole_ms,
                      whole_cpu_ms, step_ms,
                      st.get("narrow_cpu_ms"), candidates, st.get("vf_tests"), st.get("ee_tests"), impacts.vf.size(),
                      impacts.ee.size(), st.get("conservative_hits"), collision_free_step(impacts), rss);
        md << line;
        std::printf("%s", line);
        std::fflush(stdout);
        std::snprintf(line, sizeof line,
                      "{\"scene\":\"%s\",\"faces\":%d,\"delta\":%.17g,\"threads\":%s,\"method\":\"%s\",\"broad_ms\":%.3f,"
                      "\"narrow_ms\":%.3f,\"whole_ms\":%.3f,\"whole_cpu_ms\":%.3f,\"step_only_ms\":%.3f,\"narrow_thread_ms\":%.3f,\"candidates\":%zu,"
                      "\"vf_tests\":%.0f,\"ee_tests\":%.0f,\"orphan_vf\":%.0f,\"orphan_ee\":%.0f,\"narrow_boxes\":%.0f,"
                      "\"vf_impacts\":%zu,\"ee_impacts\":%zu,\"conservative_hits\":%.0f,\"earliest_toi\":%.17g,"
                      "\"peak_rss_mb\":%.1f,\"stats\":",
                      scene.name, m0.num_faces(), delta, t.c_str(), method.c_str(), broad_ms, narrow_ms, whole_ms, whole_cpu_ms, step_ms,
                      st.get("narrow_cpu_ms"), candidates, st.get("vf_tests"), st.get("ee_tests"),
                      st.get("orphan_vf"), st.get("orphan_ee"), st.get("narrow_boxes"), impacts.vf.size(),
                      impacts.ee.size(), st.get("conservative_hits"), collision_free_step(impacts), rss);
        json << line << stats_json(st) << "}\n";
        // Written after every run, so an interrupted bench keeps what it measured.
        if (!json_path.empty()) std::ofstream(json_path) << json.str();
        if (!markdown_path.empty()) std::ofstream(markdown_path) << md.str();
      }
    }
  }
  return 0;
}
