// Mesh-level continuous collision detection (detect/continuous.hpp) on the five real frame
// pairs of ../shared/data/sample-scalable-ccd, at δ = 0 and δ = 1e-3 × the first frame's
// bounding-box diagonal, with 1 and 2 threads.
//
// Per run: the broad phase alone (`ContinuousQuery::count_candidates`: refit or sort, then the
// candidate stream counted and dropped), then the whole query; narrow ms = whole − broad
// (the narrow phase runs inside the stream, on the broad phase's threads), its thread time,
// candidates, narrow-phase tests, impacts, conservative-only hits, the earliest TOI, the time of
// `ContinuousQuery::collision_free_step` alone (checked equal to the impacts' earliest TOI) and the
// process's peak resident memory during the run (VmHWM, reset before each run through
// /proc/self/clear_refs).
//
//   ccd_mesh_bench [--data DIR] [--scenes a,b] [--threads 1,2] [--method kdop] [--json FILE] [--markdown FILE]
#include <crumple/core/error.hpp>
#include <crumple/core/json.hpp>
#include <crumple/core/timing.hpp>
#include <crumple/detect/continuous.hpp>
#include <crumple/io/mesh_io.hpp>

#include <algorithm>
#include <chrono>
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
  std::vector<std::string> only, threads_list{"1", "2"};
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
    else if (a == "--method") method = value();
    else if (a == "--json") json_path = value();
    else if (a == "--markdown") markdown_path = value();
    else {
      std::fprintf(stderr,
                   "usage: ccd_mesh_bench [--data DIR] [--scenes a,b] [--threads 1,2] [--method SPEC] [--json FILE] "
                   "[--markdown FILE]\n");
      return 2;
    }
  }
  std::ostringstream json, md;
  md << "| scene | faces | delta | threads | broad ms | narrow ms | whole ms | step-only ms | narrow thread ms | "
        "candidates | vf tests | ee tests | impacts (vf + ee) | conservative-only | earliest toi | peak RSS MB |\n"
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n";
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
    for (const Scalar delta : {0.0, 1e-3 * diag}) {
      for (const std::string& t : threads_list) {
        ContinuousOptions options;
        options.min_separation = delta;
        options.method = MethodSpec::parse(method);
        options.threads = std::atoi(t.c_str());
        reset_peak_rss();
        ContinuousQuery query(m0.topology_ptr(), options);
        // Broad phase alone, then the whole query (its own broad phase included).
        const auto b0 = std::chrono::steady_clock::now();
        const std::size_t candidates = query.count_candidates(m0.positions(), m1.positions());
        const double broad_ms = ms_since(b0);
        ImpactSet impacts;
        const auto q0 = std::chrono::steady_clock::now();
        query.query(m0.positions(), m1.positions(), impacts);
        const double whole_ms = ms_since(q0);
        const double rss = peak_rss_mb();
        const DetectorStats st = query.stats();
        const double narrow_ms = whole_ms - broad_ms;
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
                      "| %s | %d | %.4g | %s | %.1f | %.1f | %.1f | %.1f | %.1f | %zu | %.0f | %.0f | %zu + %zu | %.0f | "
                      "%.6g | %.0f |\n",
                      scene.name, m0.num_faces(), delta, t.c_str(), broad_ms, narrow_ms, whole_ms, step_ms,
                      st.get("narrow_cpu_ms"), candidates, st.get("vf_tests"), st.get("ee_tests"), impacts.vf.size(),
                      impacts.ee.size(), st.get("conservative_hits"), collision_free_step(impacts), rss);
        md << line;
        std::printf("%s", line);
        std::fflush(stdout);
        std::snprintf(line, sizeof line,
                      "{\"scene\":\"%s\",\"faces\":%d,\"delta\":%.17g,\"threads\":%s,\"method\":\"%s\",\"broad_ms\":%.3f,"
                      "\"narrow_ms\":%.3f,\"whole_ms\":%.3f,\"step_only_ms\":%.3f,\"narrow_thread_ms\":%.3f,\"candidates\":%zu,"
                      "\"vf_tests\":%.0f,\"ee_tests\":%.0f,\"orphan_vf\":%.0f,\"orphan_ee\":%.0f,\"narrow_boxes\":%.0f,"
                      "\"vf_impacts\":%zu,\"ee_impacts\":%zu,\"conservative_hits\":%.0f,\"earliest_toi\":%.17g,"
                      "\"peak_rss_mb\":%.1f,\"stats\":",
                      scene.name, m0.num_faces(), delta, t.c_str(), method.c_str(), broad_ms, narrow_ms, whole_ms, step_ms,
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
